"""CDR (de)serialisation of the bag's messages, vectorised with numpy.

CDR templates: serialise one message with marker values, then patch stamps and values with numpy.
Parsing reads them back the same way when all messages share one length and frame_id (the generic
``rosbags`` deserialiser handles everything else).
"""

from __future__ import annotations

import struct

import numpy as np

from riann_ros.bagio.layout import BOOL_TYPE, IMU_TYPE, MAG_TYPE, QUAT_TYPE, STRING_TYPE, WORLD_FRAME, typestore
from riann_ros.stamps import join_ns, split_ns, to_ns

# Little-endian CDR of a message that starts with a std_msgs/Header: 4-byte encapsulation header (byte 1
# is 1 for little endian), stamp.sec (int32) at 4, stamp.nanosec (uint32) at 8, the frame_id length
# (uint32, counting the terminating NUL) at 12 and the frame_id bytes from 16.
_SEC, _NSEC, _FRAME_LEN, _FRAME = 4, 8, 12, 16


# --------------------------------------------------------------------------------------------------
# Serialising
# --------------------------------------------------------------------------------------------------

_MARKERS = [1.0 + k / 1024.0 + 1e-13 * k for k in range(1, 11)]


def _find(buf: bytes, value: float) -> int:
    needle = struct.pack("<d", value)
    pos = buf.find(needle)
    if pos < 0 or buf.find(needle, pos + 1) >= 0:  # pragma: no cover - defensive
        raise RuntimeError("CDR template marker not unique")
    return pos


def _header(frame_id: str):
    ts = typestore()
    t = ts.types["builtin_interfaces/msg/Time"]
    h = ts.types["std_msgs/msg/Header"]
    return h(stamp=t(sec=0, nanosec=0), frame_id=frame_id)


def _imu_template(frame_id: str) -> tuple[np.ndarray, list[int], list[int]]:
    """Serialised Imu bytes and the byte offsets of (gyr x,y,z) and (acc x,y,z)."""
    ts = typestore()
    v3 = ts.types["geometry_msgs/msg/Vector3"]
    q = ts.types["geometry_msgs/msg/Quaternion"]
    m = _MARKERS
    cov = np.zeros(9)
    ocov = np.zeros(9)
    ocov[0] = -1.0
    msg = ts.types[IMU_TYPE](
        header=_header(frame_id),
        orientation=q(x=0.0, y=0.0, z=0.0, w=1.0),
        orientation_covariance=ocov,
        angular_velocity=v3(x=m[0], y=m[1], z=m[2]),
        angular_velocity_covariance=cov,
        linear_acceleration=v3(x=m[3], y=m[4], z=m[5]),
        linear_acceleration_covariance=cov,
    )
    buf = bytes(ts.serialize_cdr(msg, IMU_TYPE))
    gyr = [_find(buf, m[k]) for k in range(3)]
    acc = [_find(buf, m[k]) for k in range(3, 6)]
    return np.frombuffer(buf, dtype=np.uint8), gyr, acc


def _quat_template(frame_id: str) -> tuple[np.ndarray, list[int]]:
    """Serialised QuaternionStamped bytes and the offsets of x, y, z, w."""
    ts = typestore()
    q = ts.types["geometry_msgs/msg/Quaternion"]
    m = _MARKERS
    msg = ts.types[QUAT_TYPE](header=_header(frame_id), quaternion=q(x=m[6], y=m[7], z=m[8], w=m[9]))
    buf = bytes(ts.serialize_cdr(msg, QUAT_TYPE))
    return np.frombuffer(buf, dtype=np.uint8), [_find(buf, m[k]) for k in range(6, 10)]


def _mag_template(frame_id: str) -> tuple[np.ndarray, list[int]]:
    """Serialised MagneticField bytes (covariance all 0: unknown) and the offsets of x, y, z."""
    ts = typestore()
    v3 = ts.types["geometry_msgs/msg/Vector3"]
    m = _MARKERS
    msg = ts.types[MAG_TYPE](header=_header(frame_id), magnetic_field=v3(x=m[0], y=m[1], z=m[2]),
                             magnetic_field_covariance=np.zeros(9))
    buf = bytes(ts.serialize_cdr(msg, MAG_TYPE))
    return np.frombuffer(buf, dtype=np.uint8), [_find(buf, m[k]) for k in range(3)]


def _patch_stamps(rows: np.ndarray, stamps_ns: np.ndarray) -> None:
    sec, nsec = split_ns(stamps_ns)
    rows[:, _SEC : _SEC + 4] = sec.astype("<i4").view(np.uint8).reshape(-1, 4)
    rows[:, _NSEC : _NSEC + 4] = nsec.astype("<u4").view(np.uint8).reshape(-1, 4)


def _patch_f64(rows: np.ndarray, offsets: list[int], values: np.ndarray) -> None:
    for k, off in enumerate(offsets):
        col = np.ascontiguousarray(values[:, k], dtype="<f8")
        rows[:, off : off + 8] = col.view(np.uint8).reshape(-1, 8)


def imu_messages(stamps_ns: np.ndarray, acc: np.ndarray, gyr: np.ndarray, frame_id: str) -> np.ndarray:
    """(N, L) uint8 array, row i = CDR bytes of the Imu message of sample i."""
    tpl, goff, aoff = _imu_template(frame_id)
    rows = np.tile(tpl, (len(stamps_ns), 1))
    _patch_stamps(rows, np.asarray(stamps_ns, dtype=np.int64))
    _patch_f64(rows, goff, np.asarray(gyr, dtype=np.float64))
    _patch_f64(rows, aoff, np.asarray(acc, dtype=np.float64))
    return rows


def quat_messages(stamps_ns: np.ndarray, quats_wxyz: np.ndarray, frame_id: str = WORLD_FRAME) -> np.ndarray:
    """(N, L) uint8 array, row i = CDR bytes of a QuaternionStamped (input w, x, y, z)."""
    tpl, off = _quat_template(frame_id)
    q = np.asarray(quats_wxyz, dtype=np.float64)
    rows = np.tile(tpl, (len(stamps_ns), 1))
    _patch_stamps(rows, np.asarray(stamps_ns, dtype=np.int64))
    _patch_f64(rows, off, q[:, [1, 2, 3, 0]])
    return rows


def mag_messages(stamps_ns: np.ndarray, field_t: np.ndarray, frame_id: str) -> np.ndarray:
    """(N, L) uint8 array, row i = CDR bytes of a MagneticField (tesla, sensor frame)."""
    tpl, off = _mag_template(frame_id)
    rows = np.tile(tpl, (len(stamps_ns), 1))
    _patch_stamps(rows, np.asarray(stamps_ns, dtype=np.int64))
    _patch_f64(rows, off, np.asarray(field_t, dtype=np.float64))
    return rows


def _serialize(msg, msgtype: str) -> bytes:
    return bytes(typestore().serialize_cdr(msg, msgtype))


def _bool_msg(value: bool) -> bytes:
    return _serialize(typestore().types[BOOL_TYPE](data=bool(value)), BOOL_TYPE)


def _string_msg(text: str) -> bytes:
    return _serialize(typestore().types[STRING_TYPE](data=text), STRING_TYPE)


# --------------------------------------------------------------------------------------------------
# Parsing
# --------------------------------------------------------------------------------------------------


def _uniform_rows(raws: list[bytes], length: int) -> np.ndarray | None:
    """Stack little-endian CDR messages of equal length and identical frame_id into an (N, L) array."""
    if not raws or any(len(r) != length for r in raws):
        return None
    rows = np.frombuffer(b"".join(raws), dtype=np.uint8).reshape(len(raws), length)
    if not (rows[:, 1] == 1).all():  # big-endian CDR: use the generic deserialiser
        return None
    head = rows[0, _FRAME_LEN : _FRAME + int.from_bytes(rows[0, _FRAME_LEN:_FRAME].tobytes(), "little")]
    if not (rows[:, _FRAME_LEN : _FRAME_LEN + len(head)] == head).all():
        return None
    return rows


def _stamps_of(rows: np.ndarray) -> np.ndarray:
    sec = rows[:, _SEC : _SEC + 4].copy().view("<i4").reshape(-1)
    nsec = rows[:, _NSEC : _NSEC + 4].copy().view("<u4").reshape(-1)
    return join_ns(sec, nsec)


def _f64_cols(rows: np.ndarray, offsets: list[int]) -> np.ndarray:
    out = np.empty((len(rows), len(offsets)), dtype=np.float64)
    for k, off in enumerate(offsets):
        out[:, k] = rows[:, off : off + 8].copy().view("<f8").reshape(-1)
    return out


def _frame_of(raw: bytes) -> str:
    (n,) = struct.unpack_from("<I", raw, _FRAME_LEN)
    return raw[_FRAME : _FRAME + max(n - 1, 0)].decode("utf-8", errors="replace")


def parse_imu(raws: list[bytes]) -> tuple[np.ndarray, np.ndarray, np.ndarray, str]:
    """stamps_ns, acc (N,3), gyr (N,3) and the first frame_id of serialised Imu messages."""
    if not raws:
        return np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3)), ""
    frame = _frame_of(raws[0]) if raws[0][1] == 1 else ""
    tpl, goff, aoff = _imu_template(frame)
    rows = _uniform_rows(raws, len(tpl))
    if rows is not None:
        return _stamps_of(rows), _f64_cols(rows, aoff), _f64_cols(rows, goff), frame
    ts = typestore()
    stamps = np.empty(len(raws), np.int64)
    acc = np.empty((len(raws), 3))
    gyr = np.empty((len(raws), 3))
    for i, r in enumerate(raws):
        m = ts.deserialize_cdr(r, IMU_TYPE)
        stamps[i] = to_ns(m.header.stamp)
        a, g = m.linear_acceleration, m.angular_velocity
        acc[i] = (a.x, a.y, a.z)
        gyr[i] = (g.x, g.y, g.z)
        if i == 0:
            frame = m.header.frame_id
    return stamps, acc, gyr, frame


def _parse_stamped(raws: list[bytes], template, msgtype: str, width: int, values) -> tuple[np.ndarray, np.ndarray]:
    """stamps_ns and the (N, width) float fields at ``template``'s offsets of serialised stamped messages: the
    vectorised path when all share one layout, else the generic deserialiser with ``values(msg)``."""
    if not raws:
        return np.zeros(0, np.int64), np.zeros((0, width))
    frame = _frame_of(raws[0]) if raws[0][1] == 1 else ""
    tpl, off = template(frame)
    rows = _uniform_rows(raws, len(tpl))
    if rows is not None:
        return _stamps_of(rows), _f64_cols(rows, off)
    ts = typestore()
    stamps = np.empty(len(raws), np.int64)
    out = np.empty((len(raws), width))
    for i, r in enumerate(raws):
        m = ts.deserialize_cdr(r, msgtype)
        stamps[i] = to_ns(m.header.stamp)
        out[i] = values(m)
    return stamps, out


def parse_quats(raws: list[bytes]) -> tuple[np.ndarray, np.ndarray]:
    """stamps_ns and quaternions (N, 4) w, x, y, z of serialised QuaternionStamped messages."""
    stamps, xyzw = _parse_stamped(raws, _quat_template, QUAT_TYPE, 4,
                                  lambda m: (m.quaternion.x, m.quaternion.y, m.quaternion.z, m.quaternion.w))
    return stamps, xyzw[:, [3, 0, 1, 2]]


def parse_mags(raws: list[bytes]) -> tuple[np.ndarray, np.ndarray]:
    """stamps_ns and fields (N, 3) in tesla of serialised MagneticField messages."""
    return _parse_stamped(raws, _mag_template, MAG_TYPE, 3,
                          lambda m: (m.magnetic_field.x, m.magnetic_field.y, m.magnetic_field.z))
