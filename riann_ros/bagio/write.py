"""Writing bags: a :class:`~riann_ros.recording.Recording` as a bag, and a copy of a bag with estimate topics."""

from __future__ import annotations

import heapq
import json
import os
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from riann_ros.bagio.atomic import _AtomicBag
from riann_ros.bagio.cdr import _bool_msg, _string_msg, imu_messages, mag_messages, quat_messages
from riann_ros.bagio.layout import (
    BOOL_TYPE,
    IMU_TOPIC,
    IMU_TYPE,
    INFO_KEY,
    INFO_TOPIC,
    MAG_TOPIC,
    MAG_TYPE,
    QUAT_TYPE,
    REF_TOPIC,
    SCORED_TOPIC,
    STRING_TYPE,
    BagError,
    dataset_info,
    typestore,
)
from riann_ros.bagio.read import _info_from, _opened, bag_compression, bag_storage
from riann_ros.constants import NS_PER_S
from riann_ros.recording import Recording

_MSGDEFS: dict[str, tuple[str, str]] = {}


def _add_connection(writer, topic: str, msgtype: str):
    """``writer.add_connection`` with the message definition and RIHS01 hash computed once per type."""
    if msgtype not in _MSGDEFS:
        ts = typestore()
        _MSGDEFS[msgtype] = (ts.generate_msgdef(msgtype, ros_version=2)[0], ts.hash_rihs01(msgtype))
    msgdef, rihs01 = _MSGDEFS[msgtype]
    return writer.add_connection(topic, msgtype, msgdef=msgdef, rihs01=rihs01)


def _validate(rec: Recording) -> None:
    n = len(rec)
    if n == 0:
        raise ValueError(f"recording {rec.name!r} has no samples")
    st = rec.stamps_ns
    if st[0] < 0 or st[-1] >= 2**31 * NS_PER_S:
        raise ValueError(f"recording {rec.name!r}: stamps outside the ROS time range (0 .. 2^31 s)")
    bad = np.flatnonzero(np.diff(st) <= 0)
    if len(bad):
        i = int(bad[0]) + 1
        raise ValueError(
            f"recording {rec.name!r}: time stamps not strictly increasing at sample {i} "
            f"({int(st[i - 1])} ns then {int(st[i])} ns)"
        )
    finite = np.isfinite(rec.acc).all(axis=1) & np.isfinite(rec.gyr).all(axis=1)
    if not finite.all():
        i = int(np.flatnonzero(~finite)[0])
        raise ValueError(f"recording {rec.name!r}: non-finite IMU values at sample {i}")


def write_recording(
    path: str | os.PathLike[str],
    rec: Recording,
    *,
    storage: str = "mcap",
    compression: str | None = None,
    force: bool = False,
) -> Path:
    """Write ``rec`` as a bag at ``path`` (layout in the :mod:`riann_ros.bagio` package docstring); returns the path.

    ``storage``: ``"mcap"`` or ``"sqlite3"``; ``compression``: ``None`` or ``"zstd"`` (MCAP chunk
    compression, or per-message for sqlite3). A path ending in ``.mcap`` gives a single MCAP file,
    anything else a rosbag2 directory. Refuses an existing ``path`` unless ``force``; writes to a
    temporary sibling and renames at the end, so an error or Ctrl-C leaves no partial bag.
    """
    target = Path(path)
    _validate(rec)
    info = json.dumps(dataset_info(rec), sort_keys=True)
    stamps = rec.stamps_ns
    imu_rows = imu_messages(stamps, rec.acc, rec.gyr, rec.frame_id)
    # optional per-sample topics: (topic, type, rows present, their messages)
    extra: list[tuple[str, str, np.ndarray, np.ndarray]] = []
    if rec.quat_ref is not None:
        idx = np.flatnonzero(np.isfinite(rec.quat_ref).all(axis=1))
        extra.append((REF_TOPIC, QUAT_TYPE, idx, quat_messages(stamps[idx], rec.quat_ref[idx])))
    if rec.mag is not None:
        idx = np.flatnonzero(np.isfinite(rec.mag).all(axis=1))
        extra.append((MAG_TOPIC, MAG_TYPE, idx, mag_messages(stamps[idx], rec.mag[idx], rec.frame_id)))
    mask = rec.score_mask
    change = np.concatenate([[0], np.flatnonzero(mask[1:] != mask[:-1]) + 1])
    bool_bytes = {True: _bool_msg(True), False: _bool_msg(False)}

    with _AtomicBag(target, storage, compression, force) as writer:
        writer.set_custom_data(INFO_KEY, info)
        c_info = _add_connection(writer, INFO_TOPIC, STRING_TYPE)
        c_imu = _add_connection(writer, IMU_TOPIC, IMU_TYPE)
        # per sample: -1 = no message of that topic, else the row of its message
        rows_at = []
        for topic, msgtype, idx, rows in extra:
            row_of = np.full(len(rec), -1, dtype=np.int64)
            row_of[idx] = np.arange(len(idx))
            rows_at.append((_add_connection(writer, topic, msgtype), row_of.tolist(), rows))
        c_scored = _add_connection(writer, SCORED_TOPIC, BOOL_TYPE)
        write = writer.write
        write(c_info, int(stamps[0]), _string_msg(info))
        is_change = np.zeros(len(rec), dtype=bool)
        is_change[change] = True
        for i, t in enumerate(stamps.tolist()):
            if is_change[i]:
                write(c_scored, t, bool_bytes[bool(mask[i])])
            write(c_imu, t, imu_rows[i].tobytes())
            for conn, at, rows in rows_at:
                if at[i] >= 0:
                    write(conn, t, rows[at[i]].tobytes())
    return target


def _copy_connections(src: Path, reader, writer) -> dict:
    """Add the connections of ``reader`` to ``writer``; returns {input connection id: output connection}.

    Input connections with the same topic, type and serialisation format (a topic recorded from several
    publishers) share one output connection that offers all their QoS profiles, as rosbag2 records such a
    topic; rosbags' Writer refuses a second connection identical to an existing one.
    """
    groups: dict[tuple[str, str, str], list] = {}
    for c in reader.connections:
        fmt = getattr(c.ext, "serialization_format", "cdr")
        groups.setdefault((c.topic, c.msgtype, fmt), []).append(c)
    cmap = {}
    for (topic, msgtype, fmt), conns in groups.items():
        c = conns[0]
        known = msgtype in typestore().types
        use_store = known and not (c.digest and c.msgdef.data)
        if not use_store and not (c.digest and c.msgdef.data):
            raise BagError(src, f"topic {topic}: type {msgtype} has no definition or hash to copy")
        out = writer.add_connection(
            topic,
            msgtype,
            typestore=typestore() if use_store else None,
            msgdef=None if use_store else c.msgdef.data,
            rihs01=None if use_store else c.digest,
            serialization_format=fmt,
            offered_qos_profiles=[q for x in conns for q in getattr(x.ext, "offered_qos_profiles", [])],
        )
        for x in conns:
            cmap[x.id] = out
    return cmap


class _Estimate(NamedTuple):
    """One estimate topic ready to write: stamps and serialised messages of its finite rows."""

    topic: str
    stamps: NDArray[np.int64]
    rows: NDArray[np.uint8]


def _prepare_estimates(estimates: Mapping[str, tuple[NDArray[np.int64], NDArray[np.float64]]]) -> list[_Estimate]:
    """Check the estimate topic names and serialise the rows with a finite quaternion, in ``estimates`` order."""
    prepared = []
    for topic, (stamps, quats) in estimates.items():
        if not topic.startswith("/"):
            raise ValueError(f"estimate topic {topic!r} must start with '/'")
        if topic in (IMU_TOPIC, REF_TOPIC, SCORED_TOPIC, INFO_TOPIC, MAG_TOPIC):
            raise ValueError(f"estimate topic {topic!r} clashes with the bag layout")
        st = np.asarray(stamps, dtype=np.int64).reshape(-1)
        q = np.asarray(quats, dtype=np.float64).reshape(len(st), 4)
        ok = np.isfinite(q).all(axis=1)
        prepared.append(_Estimate(topic, st[ok], quat_messages(st[ok], q[ok])))
    return prepared


def _source_messages(reader, cmap: dict) -> Iterator[tuple[int, int, object, bytes]]:
    """``(log time, 0, output connection, raw)`` for every message of the input bag, in log-time order."""
    for c, t, raw in reader.messages():
        yield t, 0, cmap[c.id], raw


def _estimate_messages(k: int, conn, est: _Estimate) -> Iterator[tuple[int, int, object, bytes]]:
    """``(stamp, k + 1, conn, raw)`` for the messages of the ``k``-th estimate topic."""
    for t, row in zip(est.stamps.tolist(), est.rows, strict=True):
        yield t, k + 1, conn, row.tobytes()


def _merge_write(src: Path, reader, writer, prepared: list[_Estimate]) -> None:
    """Write the ``/dataset/info`` custom data, the input connections and messages and the estimate topics.

    All messages are merged by log time; at equal times the input bag's message comes first, then the
    estimate topics in ``prepared`` order.
    """
    info = _info_from(src, reader)
    if info:
        writer.set_custom_data(INFO_KEY, json.dumps(info, sort_keys=True))
    cmap = _copy_connections(src, reader, writer)
    est_conns = [_add_connection(writer, est.topic, QUAT_TYPE) for est in prepared]
    streams = [_source_messages(reader, cmap)]
    streams += [_estimate_messages(k, est_conns[k], est) for k, est in enumerate(prepared)]
    for t, _, conn, raw in heapq.merge(*streams, key=lambda x: (x[0], x[1])):
        writer.write(conn, t, raw)


def write_estimates(
    src: str | os.PathLike[str],
    dst: str | os.PathLike[str],
    estimates: Mapping[str, tuple[NDArray[np.int64], NDArray[np.float64]]],
    *,
    force: bool = False,
    storage: str | None = None,
    compression: str | None = "same",
) -> Path:
    """Copy bag ``src`` to ``dst`` adding one ``QuaternionStamped`` topic per ``estimates`` entry.

    ``estimates[topic] = (stamps_ns (N,), quats (N, 4) w, x, y, z)``; rows with a non-finite quaternion
    are skipped; ``frame_id`` is ``"world"``. Messages are written in log-time order. Storage and
    compression are those of ``src`` unless given (``compression``: ``"same"``, ``None`` or ``"zstd"``);
    same refuse-overwrite/atomic rules as :func:`write_recording`.
    """
    src, dst = Path(src), Path(dst)
    if dst.resolve() == src.resolve():
        raise FileExistsError(f"{dst}: output is the input bag; choose another output path")
    storage = storage or ("mcap" if dst.suffix == ".mcap" else bag_storage(src))
    if compression == "same":
        compression = bag_compression(src)
    prepared = _prepare_estimates(estimates)
    with _opened(src) as reader:
        try:
            with _AtomicBag(dst, storage, compression, force) as writer:
                _merge_write(src, reader, writer, prepared)
        except (BagError, FileExistsError, ValueError, KeyboardInterrupt):
            raise
        except Exception as e:
            raise BagError(src, f"copying to {dst} failed ({type(e).__name__}: {e})") from e
    return dst
