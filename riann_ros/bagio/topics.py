"""Orientation topics of any bag — a ground truth, estimates a user recorded from their own filter — aligned onto
the IMU samples chunk by chunk (ROS-free: ``rosbags`` only).

Types with an orientation (:data:`ORIENTATION_TYPES`): ``sensor_msgs/msg/Imu`` (``orientation``; a message whose
``orientation_covariance[0]`` is -1 has none), ``geometry_msgs/msg/QuaternionStamped``, ``geometry_msgs/msg/
PoseStamped``, ``geometry_msgs/msg/PoseWithCovarianceStamped`` and ``nav_msgs/msg/Odometry``. The header stamp
is the message's time (plus ``offset``), not the log time.

An estimate topic's σ (``sigma=True``, :func:`sigmas_of_variances`): from the orientation covariance of the types
that carry one (:data:`COVARIANCE_FIELDS`: ``Imu.orientation_covariance``, the rotation block of a pose
covariance), the inclination σ as the root of the mean of the variances about x and y (the covariance is about
the fixed frame's axes, REP-145, and an inclination error turns about a horizontal axis) and the heading σ as
the root of the variance about z; NaN where the covariance says nothing (all zero: unknown; negative or not
finite) or the type has none.

Alignment onto a sample at stamp ``t`` (:func:`interpolate`): a message stamped exactly ``t`` gives its
orientation; otherwise the two messages around ``t`` are slerped when they are at most ``max_gap`` apart;
otherwise the nearer one is held if it is at most ``max_gap / 2`` away (the ends of a topic, the edges of a
gap); otherwise the sample has none (NaN).

:func:`iter_topic_chunks` reads the IMU samples in chunks (:func:`~riann_ros.bagio.read.iter_imu_chunks`) and,
with a reader of its own per topic, only as much of each orientation topic as the chunk needs, so memory is
bounded by the chunk size and the topics' latency, not by the bag's length.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from riann_ros import defaults
from riann_ros import quaternion as quat
from riann_ros.bagio.cdr import _f64_cols, _stamps_of, _uniform_rows
from riann_ros.bagio.layout import IMU_TOPIC, IMU_TYPE, MAG_TOPIC, BagError, typestore
from riann_ros.bagio.read import MagPairer, _opened, iter_imu_chunks
from riann_ros.constants import NS_PER_S
from riann_ros.recording import Recording
from riann_ros.stamps import to_ns

#: message type → the attribute path of its orientation
ORIENTATION_TYPES: dict[str, tuple[str, ...]] = {
    IMU_TYPE: ("orientation",),
    "geometry_msgs/msg/QuaternionStamped": ("quaternion",),
    "geometry_msgs/msg/PoseStamped": ("pose", "orientation"),
    "geometry_msgs/msg/PoseWithCovarianceStamped": ("pose", "pose", "orientation"),
    "nav_msgs/msg/Odometry": ("pose", "pose", "orientation"),
}
#: message type → the attribute path of its orientation covariance and the indices of the variances about x, y, z
COVARIANCE_FIELDS: dict[str, tuple[tuple[str, ...], tuple[int, int, int]]] = {
    IMU_TYPE: (("orientation_covariance",), (0, 4, 8)),
    "geometry_msgs/msg/PoseWithCovarianceStamped": (("pose", "covariance"), (21, 28, 35)),
    "nav_msgs/msg/Odometry": (("pose", "covariance"), (21, 28, 35)),
}
READ_BATCH = 4096  # messages parsed at a time
_MARK = (1.0 + 1 / 1024 + 3e-13, 1.0 + 2 / 1024 + 5e-13, 1.0 + 3 / 1024 + 7e-13, 1.0 + 4 / 1024 + 11e-13,
         1.0 + 5 / 1024 + 13e-13)


def orientation_topic(path: Path, reader, topic: str) -> tuple[str, list]:
    """The type and connections of ``topic``; BagError when it is missing or has no orientation."""
    conns = [c for c in reader.connections if c.topic == topic]
    if not conns:
        have = ", ".join(sorted({c.topic for c in reader.connections})) or "none"
        raise BagError(path, f"no {topic} topic (topics: {have})")
    types = sorted({c.msgtype for c in conns})
    if len(types) > 1 or types[0] not in ORIENTATION_TYPES:
        raise BagError(path, f"topic {topic} has type {', '.join(types)}; an orientation topic must be one of "
                       f"{', '.join(ORIENTATION_TYPES)}")
    return types[0], conns


def _orientation(msg, msgtype: str):
    obj = msg
    for name in ORIENTATION_TYPES[msgtype]:
        obj = getattr(obj, name)
    return obj


def _covariance_slot(msg, msgtype: str) -> tuple[object, str]:
    """The message (or sub-message) holding the orientation covariance of ``msg``, and the field's name."""
    *parents, name = COVARIANCE_FIELDS[msgtype][0]
    holder = msg
    for p in parents:
        holder = getattr(holder, p)
    return holder, name


def _covariance(msg, msgtype: str):
    return getattr(*_covariance_slot(msg, msgtype))


def _template(raw: bytes, msgtype: str) -> tuple[int, list[int], int | None]:
    """The length of ``raw``, the byte offsets of its orientation x, y, z, w and of its orientation covariance's
    first element (None: the type has none), found by serialising it again with marker values."""
    ts = typestore()
    msg = ts.deserialize_cdr(raw, msgtype)
    o = _orientation(msg, msgtype)
    o.x, o.y, o.z, o.w = _MARK[:4]
    has_cov = msgtype in COVARIANCE_FIELDS
    if has_cov:
        holder, name = _covariance_slot(msg, msgtype)
        cov = np.array(getattr(holder, name), dtype=np.float64)
        cov[0] = _MARK[4]
        setattr(holder, name, cov)
    buf = bytes(ts.serialize_cdr(msg, msgtype))
    offs = [buf.find(struct.pack("<d", m)) for m in _MARK[: 5 if has_cov else 4]]
    if min(offs) < 0 or any(buf.find(struct.pack("<d", m), o + 1) >= 0 for m, o in zip(_MARK, offs, strict=False)):
        raise RuntimeError("orientation template markers not found once")  # pragma: no cover - defensive
    return len(buf), offs[:4], (offs[4] if has_cov else None)


def sigmas_of_variances(v: NDArray[np.float64]) -> NDArray[np.float64]:
    """σ (N, 2) rad, inclination and heading, from the variances (N, 3) rad² about x, y, z (module docstring)."""
    v = np.asarray(v, dtype=np.float64)
    out = np.full((len(v), 2), np.nan)
    ok = np.isfinite(v).all(axis=1) & (v >= 0.0).all(axis=1) & (v > 0.0).any(axis=1)
    out[ok, 0] = np.sqrt((v[ok, 0] + v[ok, 1]) / 2.0)
    out[ok, 1] = np.sqrt(v[ok, 2])
    return out


def _clean(q: NDArray[np.float64], no_orientation: NDArray[np.bool_] | None) -> NDArray[np.float64]:
    """Unit quaternions; NaN rows for messages without an orientation (zero quaternion, Imu covariance -1)."""
    norm = np.linalg.norm(q, axis=1, keepdims=True)
    bad = ~(np.isfinite(norm[:, 0]) & (norm[:, 0] > 1e-6))
    if no_orientation is not None:
        bad |= no_orientation
    out = q / np.where(bad[:, None], 1.0, norm)
    out[bad] = np.nan
    return out


def parse_orientations(raws: Sequence[bytes], msgtype: str,
                       sigma: bool = False) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Header stamps (ns) and orientations (N, 4) w, x, y, z of serialised messages of an orientation type (NaN
    rows: no orientation); with ``sigma``, (N, 6): the σ of :func:`sigmas_of_variances` appended (NaN: none).
    Vectorised when the messages share one length and frame_id, generic otherwise."""
    width = 6 if sigma else 4
    if not raws:
        return np.zeros(0, np.int64), np.zeros((0, width))
    var_idx = COVARIANCE_FIELDS[msgtype][1] if msgtype in COVARIANCE_FIELDS else None
    fast = raws[0][1] == 1  # little-endian CDR
    if fast:
        length, offs, cov = _template(raws[0], msgtype)
        rows = _uniform_rows(list(raws), length)
        if rows is not None:
            xyzw = _f64_cols(rows, offs)
            missing = _f64_cols(rows, [cov])[:, 0] == -1.0 if cov is not None and msgtype == IMU_TYPE else None
            q = _clean(xyzw[:, [3, 0, 1, 2]], missing)
            if sigma:
                var = (_f64_cols(rows, [cov + 8 * k for k in var_idx]) if cov is not None and var_idx is not None
                       else np.full((len(q), 3), np.nan))
                q = np.hstack([q, sigmas_of_variances(var)])
            return _stamps_of(rows), q
    ts = typestore()
    stamps = np.empty(len(raws), np.int64)
    q = np.empty((len(raws), 4))
    var = np.full((len(raws), 3), np.nan)
    missing = np.zeros(len(raws), bool)
    for i, r in enumerate(raws):
        m = ts.deserialize_cdr(r, msgtype)
        stamps[i] = to_ns(m.header.stamp)
        o = _orientation(m, msgtype)
        q[i] = (o.w, o.x, o.y, o.z)
        if msgtype == IMU_TYPE:
            missing[i] = m.orientation_covariance[0] == -1.0
        if var_idx is not None:
            var[i] = np.asarray(_covariance(m, msgtype), dtype=np.float64)[list(var_idx)]
    q = _clean(q, missing)
    return stamps, (np.hstack([q, sigmas_of_variances(var)]) if sigma else q)


def iter_orientations(path: str | os.PathLike[str], topic: str, batch: int = READ_BATCH,
                      sigma: bool = False) -> Iterator[tuple[NDArray[np.int64], NDArray[np.float64]]]:
    """``(stamps_ns, quats)`` of ``topic`` in batches of at most ``batch`` messages, in log-time order, with a
    reader of its own; with ``sigma`` each row has the σ columns of :func:`parse_orientations`."""
    path = Path(path)
    with _opened(path) as reader:
        msgtype, conns = orientation_topic(path, reader, topic)
        raws: list[bytes] = []
        try:
            for _, _, raw in reader.messages(connections=conns):
                raws.append(raw)
                if len(raws) >= batch:
                    yield parse_orientations(raws, msgtype, sigma)
                    raws = []
            if raws:
                yield parse_orientations(raws, msgtype, sigma)
        except (BagError, KeyboardInterrupt, GeneratorExit):
            raise
        except Exception as e:
            raise BagError(path, f"topic {topic}: unreadable ({type(e).__name__}: {e})") from e


def interpolate(st: NDArray[np.int64], q: NDArray[np.float64], t: NDArray[np.int64],
                max_gap_ns: int) -> NDArray[np.float64]:
    """Orientations at stamps ``t`` from messages at sorted, unique stamps ``st`` (rules in the module docstring);
    columns after the first four (σ) are interpolated linearly where the quaternions are slerped."""
    out = np.full((len(t), q.shape[1]), np.nan)
    n = len(st)
    if n == 0 or len(t) == 0:
        return out
    j = np.searchsorted(st, t, side="left")
    has_a, has_b = j > 0, j < n
    ja, jb = np.maximum(j - 1, 0), np.minimum(j, n - 1)
    exact = has_b & (st[jb] == t)
    da = (t - st[ja]).astype(np.float64)
    db = (st[jb] - t).astype(np.float64)
    span = (st[jb] - st[ja]).astype(np.float64)
    both = ~exact & has_a & has_b & (span <= max_gap_ns)
    out[exact] = q[jb[exact]]
    if both.any():
        w = da[both] / span[both]
        out[both, :4] = quat.slerp(q[ja[both], :4], q[jb[both], :4], w)
        out[both, 4:] = q[ja[both], 4:] * (1.0 - w)[:, None] + q[jb[both], 4:] * w[:, None]
    rest = ~exact & ~both
    half = max_gap_ns / 2
    use_a = rest & has_a & (da <= half) & (~has_b | (da <= db))
    use_b = rest & ~use_a & has_b & (db <= half)
    out[use_a] = q[ja[use_a]]
    out[use_b] = q[jb[use_b]]
    return out


class Aligner:
    """One orientation topic served at consecutive chunks of sample stamps (:meth:`at`), reading its messages only
    as far as needed and forgetting those no later sample can use."""

    def __init__(self, batches: Iterator[tuple[NDArray[np.int64], NDArray[np.float64]]], offset_ns: int = 0,
                 max_gap_ns: int = round(defaults.MAX_GAP_S * NS_PER_S), width: int = 4) -> None:
        self.batches = batches  # rows of ``width`` columns: a quaternion, then σ columns (``sigma=True`` reads)
        self.offset = int(offset_ns)
        self.gap = int(max_gap_ns)
        self.st = np.zeros(0, np.int64)
        self.q = np.zeros((0, width))
        self.latest: int | None = None  # the largest stamp read so far
        self.exhausted = False
        self.messages = 0  # read so far, with an orientation
        self.span: tuple[int, int] | None = None  # first and last stamp read (offset added)

    def _read_until(self, horizon: int) -> None:
        parts_s, parts_q = [self.st], [self.q]
        while not self.exhausted and (self.latest is None or self.latest <= horizon):
            try:
                s, q = next(self.batches)
            except StopIteration:
                self.exhausted = True
                break
            ok = np.isfinite(q[:, :4]).all(axis=1)
            s, q = s[ok] + self.offset, q[ok]
            if len(s):
                self.messages += len(s)
                lo, hi = int(s.min()), int(s.max())
                self.span = (lo, hi) if self.span is None else (min(self.span[0], lo), max(self.span[1], hi))
                self.latest = hi if self.latest is None else max(self.latest, hi)
                parts_s.append(s)
                parts_q.append(q)
        if len(parts_s) > 1:
            s, q = np.concatenate(parts_s), np.concatenate(parts_q)
            order = np.argsort(s, kind="stable")
            s, q = s[order], q[order]
            keep = np.r_[s[1:] != s[:-1], True]  # one message per stamp: the last one
            self.st, self.q = s[keep], q[keep]

    def at(self, stamps: NDArray[np.int64]) -> NDArray[np.float64]:
        """Orientations (N, 4) at ``stamps`` (increasing, after those of the previous call); NaN rows: none."""
        if not len(stamps):
            return np.zeros((0, self.q.shape[1]))
        last = int(stamps[-1])
        self._read_until(last + self.gap)
        out = interpolate(self.st, self.q, stamps, self.gap)
        cut = int(np.searchsorted(self.st, last - self.gap, side="left"))
        self.st, self.q = self.st[cut:], self.q[cut:]
        return out

    def close(self) -> None:
        close = getattr(self.batches, "close", None)
        if close is not None:
            close()


def iter_topic_chunks(path: str | os.PathLike[str], chunk: int = 100_000, *, imu_topic: str = IMU_TOPIC,
                      reference_topic: str | None = None, estimate_topics: Sequence[str] = (), t_offset_ns: int = 0,
                      max_gap_ns: int = round(defaults.MAX_GAP_S * NS_PER_S), pair_mag: MagPairer | None = None,
                      mag_topic: str = MAG_TOPIC) -> Iterator[tuple[Recording, dict[str, NDArray[np.float64]]]]:
    """The IMU samples of ``imu_topic`` in chunks, each with the orientations of ``estimate_topics`` at its samples
    (stamps + ``t_offset_ns``; (N, 6): w, x, y, z and the σ of :func:`sigmas_of_variances`) and, with
    ``reference_topic``, that topic as its reference (instead of the layout's ``/ground_truth/attitude``). The
    score mask is the layout's ``/ground_truth/scored`` if present, else all scored; the magnetometer
    (``mag_topic``) is paired by ``pair_mag`` (:func:`~riann_ros.bagio.read.iter_imu_chunks`). BagError for missing
    topics or topics without an orientation."""
    path = Path(path)
    topics = [t for t in (reference_topic, *estimate_topics) if t]
    with _opened(path) as reader:
        for t in topics:
            orientation_topic(path, reader, t)
    ref = Aligner(iter_orientations(path, reference_topic), 0, max_gap_ns) if reference_topic else None
    ests = {t: Aligner(iter_orientations(path, t, sigma=True), t_offset_ns, max_gap_ns, width=6)
            for t in estimate_topics}
    try:
        for rec in iter_imu_chunks(path, chunk, imu_topic=imu_topic, reference=reference_topic is None,
                                   pair_mag=pair_mag, mag_topic=mag_topic):
            if ref is not None:
                rec.quat_ref = ref.at(rec.stamps_ns)
            yield rec, {t: a.at(rec.stamps_ns) for t, a in ests.items()}
    finally:
        for a in [ref, *ests.values()]:
            if a is not None:
                a.close()
