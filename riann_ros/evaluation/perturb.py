"""Perturbations: make a recording behave like a real sensor stream, chunk by chunk (ROS-free).

``riann-bag-eval --perturb CONDITION`` (repeatable: each condition is evaluated like another rate). A
condition is ``none`` or perturbations joined with ``+``, applied in that order to each scenario
sequence, after the scenario and before the estimators:

``jitter:10/20/30ms`` / ``jitter:8-32ms``
    Irregular stamps: the next sample comes an interval later drawn uniformly from the set (or the
    range); its acc and gyr are the means of the recording's signal over that interval (the signal
    taken as piecewise linear between samples, so a short interval interpolates and a long one
    averages); the reference is slerped at the new stamp, the score mask taken from the nearest sample.
``rate:50``
    A regular stream at 50 Hz made the same way (``jitter`` with one interval): causal resampling,
    chunk by chunk. (``--rates`` resamples the whole recording with the FFT, as in the paper.)
``jitter:5-15ms:points`` / ``rate:50:points``
    The same stamps, but each sample is the signal *at* its stamp (interpolated linearly between the
    recording's samples) instead of its mean over the interval: a sensor read at irregular times, which
    is what a ROS stamp means (the measurement time).
``latency:0-20ms``
    Receive-time stamps: each sample keeps its values and its reference, but its stamp is the
    measurement time plus a delivery delay drawn uniformly from the range (stamps kept in order, at
    least 1 µs apart) — what a driver that stamps on arrival over USB, Bluetooth or a busy host
    gives. The samples underneath stay regular; only the stamps jitter.
``fifo:20ms``
    FIFO read-out: the host reads the sensor's FIFO every 20 ms (from the sequence's first stamp) and
    stamps each message on arrival, at the read time, 10 µs apart in order — a driver that polls a
    FIFO. Samples and reference unchanged; the stamps come in bursts.
``bias:3,3,0`` / ``bias:random:2``
    A constant gyroscope bias (°/s per axis) from the first sample of the sequence, or one drawn per
    sequence from N(0, (2 °/s)²) per axis.
``dropout:0.1-0.6s@10s``
    Lost messages: holes of a length drawn uniformly from the range, about every 10 s (exponential
    spacing), starting only where the sensor moves (a scored sample); the samples in a hole are removed.
``magnetic:offset:20,0,-10`` / ``magnetic:disturb:40@10-20s``
    The magnetometer (recordings without one are left as they are): a constant hard-iron offset (µT
    per sensor axis) from the first sample, or a field of 40 µT fixed in the sensor frame (a magnet or
    a steel part carried with the sensor), in a direction drawn per sequence, from 10 s to 20 s after
    the sequence's first sample.

Every random draw is seeded per sequence, condition and perturbation (``--seed``), so every estimator
sees the same perturbed stream and a bag gives the same stream whatever its chunking.
"""

from __future__ import annotations

import re
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from riann_ros import quaternion as quat
from riann_ros.recording import Recording

NONE = "none"
DEFINITIONS = {
    "jitter": "jitter:10/20/30ms (set) or jitter:8-32ms (range): each next sample an interval later drawn uniformly; "
    "acc/gyr = means of the piecewise-linear signal over the interval; reference slerped at the sample",
    "rate": "rate:HZ: a regular stream at HZ made like jitter (interval means), causal, chunk by chunk",
    "points": "jitter:...:points, rate:HZ:points: the same stamps, each sample the signal at its stamp (linear "
    "between the recording's samples) instead of the interval mean",
    "latency": "latency:LO-HIms: each stamp = the measurement time + a delay drawn uniformly from LO-HI (kept in "
    "order); samples and reference unchanged",
    "fifo": "fifo:Pms: the FIFO read every P ms from the first stamp; each message stamped at its read time, "
    "10 us apart in order; samples and reference unchanged",
    "bias": "bias:X,Y,Z (deg/s) or bias:random:SIGMA (deg/s per axis, drawn per sequence): added to the gyro "
    "from the first sample of the sequence",
    "dropout": "dropout:LO-HIs@Ts: holes of LO-HI s (uniform) about every T s (exponential spacing), starting at "
    "a scored sample; the samples in a hole are removed",
    "magnetic": "magnetic:offset:X,Y,Z (µT, sensor frame, from the first sample) or magnetic:disturb:B@T0-T1s "
    "(B µT fixed in the sensor frame, direction drawn per sequence, T0-T1 s after the first sample): added "
    "to the magnetometer; recordings without one are left as they are",
    "seeding": "per sequence, condition and perturbation: sha256 of '<seed>:<sequence>:<condition>:<index>'",
}
DRAW_BLOCK = 1024  # random intervals drawn at a time (consumed in order: independent of chunking)


class Transform(ABC):
    """A perturbation applied to one sequence: called with its pieces in order, keeps state between them."""

    @abstractmethod
    def __call__(self, rec: Recording) -> Recording: ...

    def info(self) -> dict[str, Any]:
        """What happened to this sequence (for results.json)."""
        return {}


class Perturbation(ABC):
    """A kind of perturbation with its parameters (parsed from ``kind:args``)."""

    kind: str = ""

    @abstractmethod
    def text(self) -> str:
        """The canonical ``kind:args`` form."""

    def nominal_rate(self, rate_hz: float) -> float:
        """The stream's nominal rate after this perturbation, given the rate before."""
        return rate_hz

    @abstractmethod
    def start(self, rng: np.random.Generator) -> Transform:
        """A fresh transform for one sequence."""


def _with(rec: Recording, keep: NDArray[np.bool_] | None = None, **fields: Any) -> Recording:
    """A copy of ``rec`` restricted to ``keep`` and with some fields replaced."""
    sel = slice(None) if keep is None else keep
    base: dict[str, Any] = {
        "stamps_ns": rec.stamps_ns[sel],
        "acc": rec.acc[sel],
        "gyr": rec.gyr[sel],
        "quat_ref": None if rec.quat_ref is None else rec.quat_ref[sel],
        "score_mask": rec.score_mask[sel],
        "mag": None if rec.mag is None else rec.mag[sel],
    }
    base.update(fields)
    return Recording(**base, name=rec.name, dataset=rec.dataset, source=rec.source, frame_id=rec.frame_id,
                     meta=rec.meta)


# ---------------------------------------------------------------------------------------------------
# bias
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Bias(Perturbation):
    """A constant gyro bias (°/s): fixed per axis, or drawn per sequence with standard deviation ``sigma``."""

    dps: tuple[float, float, float] | None = None
    sigma: float = 0.0
    kind = "bias"

    def text(self) -> str:
        if self.dps is None:
            return f"bias:random:{self.sigma:g}"
        return "bias:" + ",".join(f"{v:g}" for v in self.dps)

    def start(self, rng: np.random.Generator) -> Transform:
        dps = np.asarray(self.dps) if self.dps is not None else rng.normal(0.0, self.sigma, 3)
        return _AddBias(np.radians(dps))


class _AddBias(Transform):
    def __init__(self, bias: NDArray[np.float64]) -> None:
        self.bias = bias

    def __call__(self, rec: Recording) -> Recording:
        return _with(rec, gyr=rec.gyr + self.bias)

    def info(self) -> dict[str, Any]:
        return {"bias_dps": np.degrees(self.bias).round(6).tolist()}


# ---------------------------------------------------------------------------------------------------
# magnetic: hard-iron offset, disturbance window
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Magnetic(Perturbation):
    """A field added to the magnetometer (µT, sensor frame): constant from the first sample (``offset``),
    or ``strength`` µT in a direction drawn per sequence between ``t0`` and ``t1`` s after it."""

    offset: tuple[float, float, float] | None = None
    strength: float = 0.0
    t0: float = 0.0
    t1: float = 0.0
    kind = "magnetic"

    def text(self) -> str:
        if self.offset is not None:
            return "magnetic:offset:" + ",".join(f"{v:g}" for v in self.offset)
        return f"magnetic:disturb:{self.strength:g}@{self.t0:g}-{self.t1:g}s"

    def start(self, rng: np.random.Generator) -> Transform:
        if self.offset is not None:
            return _AddField(np.asarray(self.offset, dtype=float) * 1e-6, None)
        d = rng.normal(size=3)
        return _AddField(self.strength * 1e-6 * d / np.linalg.norm(d), (self.t0, self.t1))


class _AddField(Transform):
    def __init__(self, field_t: NDArray[np.float64], window: tuple[float, float] | None) -> None:
        self.field = field_t
        self.window = window
        self.first: int | None = None  # stamp of the sequence's first sample (ns)
        self.samples = 0

    def __call__(self, rec: Recording) -> Recording:
        if rec.mag is None or len(rec) == 0:
            return rec
        if self.first is None:
            self.first = int(rec.stamps_ns[0])
        on = np.ones(len(rec), dtype=bool)
        if self.window is not None:
            t = (rec.stamps_ns - self.first) * 1e-9
            on = (t >= self.window[0]) & (t < self.window[1])
        self.samples += int(on.sum())
        return _with(rec, mag=rec.mag + np.where(on[:, None], self.field, 0.0))

    def info(self) -> dict[str, Any]:
        return {"field_uT": (self.field * 1e6).round(6).tolist(), "samples": self.samples}


# ---------------------------------------------------------------------------------------------------
# jitter and rate: interval means of the piecewise-linear signal on new stamps
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Jitter(Perturbation):
    """Intervals (s) drawn uniformly from ``choices``, or from the range ``[lo, hi]`` when no choices."""

    choices: tuple[float, ...] = ()
    lo: float = 0.0
    hi: float = 0.0
    points: bool = False  # each sample the signal at its stamp, not the mean over its interval
    kind = "jitter"

    def text(self) -> str:
        if self.choices:
            return "jitter:" + "/".join(f"{v * 1e3:g}" for v in self.choices) + "ms" + self._suffix()
        return f"jitter:{self.lo * 1e3:g}-{self.hi * 1e3:g}ms" + self._suffix()

    def _suffix(self) -> str:
        return ":points" if self.points else ""

    def mean_interval(self) -> float:
        return float(np.mean(self.choices)) if self.choices else 0.5 * (self.lo + self.hi)

    def nominal_rate(self, rate_hz: float) -> float:
        return 1.0 / self.mean_interval()

    def draw(self, rng: np.random.Generator) -> Callable[[], NDArray[np.int64]]:
        if self.choices:
            ns = np.round(np.asarray(self.choices) * 1e9).astype(np.int64)
            return lambda: rng.choice(ns, DRAW_BLOCK)
        lo, hi = round(self.lo * 1e9), round(self.hi * 1e9)
        return lambda: rng.integers(lo, hi, DRAW_BLOCK, endpoint=True)

    def start(self, rng: np.random.Generator) -> Transform:
        return _IntervalMeans(self.draw(rng), self.points)


@dataclass(frozen=True)
class Rate(Jitter):
    """A regular stream at ``hz``."""

    hz: float = 100.0
    kind = "rate"

    def text(self) -> str:
        return f"rate:{self.hz:g}" + self._suffix()

    def mean_interval(self) -> float:
        return 1.0 / self.hz

    def draw(self, rng: np.random.Generator) -> Callable[[], NDArray[np.int64]]:
        # exact ns grid (1/3 ms steps alternate 333333 and 333334 ns): stamps k * 1e9 / hz, rounded
        step = 1e9 / self.hz
        state = {"k": 0}

        def block() -> NDArray[np.int64]:
            k = state["k"] + np.arange(DRAW_BLOCK + 1)
            state["k"] += DRAW_BLOCK
            return np.diff(np.round(k * step)).astype(np.int64)

        return block


class _IntervalMeans(Transform):
    """New stamps t_k = t_{k-1} + interval; sample k = mean of the signal over (t_{k-1}, t_k] (``points``: the
    signal at t_k)."""

    def __init__(self, draw: Callable[[], NDArray[np.int64]], points: bool = False) -> None:
        self._draw = draw
        self._points = points
        self._queue = np.zeros(0, np.int64)
        self._tail: Recording | None = None  # the samples needed again: from the last at or before t_prev
        self._t_prev: int | None = None
        self.emitted = 0

    def _intervals(self, n: int) -> NDArray[np.int64]:
        while len(self._queue) < n:
            self._queue = np.concatenate([self._queue, self._draw()])
        return self._queue[:n]

    def _times(self, t_prev: int, t_last: int) -> NDArray[np.int64]:
        """The new stamps after ``t_prev`` up to ``t_last``; consumes their intervals."""
        out: list[NDArray[np.int64]] = []
        while True:
            n = max(len(self._queue), DRAW_BLOCK)
            steps = self._intervals(n)
            t = t_prev + np.cumsum(steps)
            k = int(np.searchsorted(t, t_last, side="right"))
            out.append(t[:k])
            self._queue = self._queue[k:]
            if k < n:
                return np.concatenate(out)
            t_prev = int(t[-1])

    def __call__(self, rec: Recording) -> Recording:
        first = None
        if self._t_prev is None:  # the first sample starts the new stream as it is
            first, self._t_prev = rec.slice(0, 1), int(rec.stamps_ns[0])
        buf = rec if self._tail is None else _concat(self._tail, rec)
        times = self._times(self._t_prev, int(buf.stamps_ns[-1]))
        out = _interval_means(buf, np.concatenate([[self._t_prev], times]), self._points) if len(times) else None
        if len(times):
            self._t_prev = int(times[-1])
        keep_from = max(0, int(np.searchsorted(buf.stamps_ns, self._t_prev, side="right")) - 1)
        self._tail = buf.slice(keep_from)
        parts = [p for p in (first, out) if p is not None]
        result = _concat(*parts) if len(parts) > 1 else (parts[0] if parts else rec.slice(0, 0))
        self.emitted += len(result)
        return result

    def info(self) -> dict[str, Any]:
        return {"samples": self.emitted}


def _concat(*recs: Recording) -> Recording:
    has_ref = recs[0].quat_ref is not None
    return _with(
        recs[0],
        stamps_ns=np.concatenate([r.stamps_ns for r in recs]),
        acc=np.concatenate([r.acc for r in recs]),
        gyr=np.concatenate([r.gyr for r in recs]),
        quat_ref=np.concatenate([r.quat_ref for r in recs if r.quat_ref is not None]) if has_ref else None,
        score_mask=np.concatenate([r.score_mask for r in recs]),
        mag=np.concatenate([r.mag for r in recs if r.mag is not None]) if recs[0].mag is not None else None,
    )


def _interval_means(buf: Recording, edges: NDArray[np.int64], points: bool = False) -> Recording:
    """Samples at ``edges[1:]``: means of acc and gyr (piecewise linear between ``buf``'s samples) over each
    (edges[k-1], edges[k]] (``points``: their values at the edge); reference slerped at the edge, score mask
    of the nearest sample, magnetic field of the latest sample at or before the edge (a magnetometer read
    when the sample is made)."""
    t0 = int(buf.stamps_ns[0])
    t = (buf.stamps_ns - t0) * 1e-9
    x = np.concatenate([buf.acc, buf.gyr], axis=1)
    h = np.diff(t)
    area = np.concatenate([np.zeros((1, 6)), np.cumsum(0.5 * (x[1:] + x[:-1]) * h[:, None], axis=0)])
    q = (edges - t0) * 1e-9
    i = np.clip(np.searchsorted(t, q, side="right") - 1, 0, len(t) - 2) if len(t) > 1 else np.zeros(len(q), int)
    if len(t) > 1:
        d = q - t[i]
        slope = (x[i + 1] - x[i]) / h[i][:, None]
        integral = area[i] + x[i] * d[:, None] + 0.5 * slope * (d * d)[:, None]
        s = d / h[i]
    else:  # a single sample: constant signal
        integral = x[0] * (q - t[0])[:, None]
        s = np.zeros(len(q))
    if not points:
        means = np.diff(integral, axis=0) / np.diff(q)[:, None]
    elif len(t) > 1:
        means = (x[i] + slope * d[:, None])[1:]
    else:
        means = np.repeat(x[:1], len(q) - 1, axis=0)
    ref = None
    if buf.quat_ref is not None:
        ref = np.full((len(q), 4), np.nan)
        if len(t) > 1:
            a, b = buf.quat_ref[i], buf.quat_ref[i + 1]
            ok = np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1)
            ref[ok] = quat.slerp(a[ok], b[ok], np.clip(s[ok], 0.0, 1.0))
        ref = ref[1:]
    nearest = np.clip(i + np.round(np.clip(s, 0.0, 1.0)).astype(int), 0, len(t) - 1)
    mag = None
    if buf.mag is not None:
        mag = buf.mag[np.clip(np.searchsorted(t, q[1:], side="right") - 1, 0, len(t) - 1)]
    return _with(buf, None, stamps_ns=edges[1:], acc=means[:, :3], gyr=means[:, 3:],
                 quat_ref=ref, score_mask=buf.score_mask[nearest[1:]], mag=mag)


# ---------------------------------------------------------------------------------------------------
# latency and fifo: receive-time stamps
# ---------------------------------------------------------------------------------------------------
def _in_order(want: NDArray[np.int64], last: int | None, step_ns: int) -> NDArray[np.int64]:
    """Stamps ``want`` kept in order and at least ``step_ns`` apart, after ``last`` (the previous chunk's
    final stamp, None at the start): ``t'_k = max(want_k, t'_{k-1} + step)``."""
    k = np.arange(len(want), dtype=np.int64) * step_ns
    start = np.iinfo(np.int64).min // 2 if last is None else last + step_ns
    return np.maximum.accumulate(np.maximum(want - k, start)) + k

@dataclass(frozen=True)
class Latency(Perturbation):
    """Stamps later than the measurement by a delay drawn uniformly from ``lo``–``hi`` s, kept in order."""

    lo: float = 0.0
    hi: float = 0.02
    kind = "latency"

    def text(self) -> str:
        return f"latency:{self.lo * 1e3:g}-{self.hi * 1e3:g}ms"

    def start(self, rng: np.random.Generator) -> Transform:
        return _Latency(self, rng)


class _Latency(Transform):
    MIN_STEP_NS = 1000

    def __init__(self, p: Latency, rng: np.random.Generator) -> None:
        self.p = p
        self.rng = rng
        self.last: int | None = None  # the previous output stamp (ns)
        self.samples = 0

    def __call__(self, rec: Recording) -> Recording:
        n = len(rec)
        if n == 0:
            return rec
        delay = np.round(self.rng.uniform(self.p.lo, self.p.hi, n) * 1e9).astype(np.int64)
        out = _in_order(rec.stamps_ns + delay, self.last, self.MIN_STEP_NS)
        self.last = int(out[-1])
        self.samples += n
        return _with(rec, stamps_ns=out)

    def info(self) -> dict[str, Any]:
        return {"samples": self.samples}


@dataclass(frozen=True)
class Fifo(Perturbation):
    """Stamps of a FIFO read every ``period`` s: each sample stamped at the first read at or after it."""

    period: float = 0.02
    kind = "fifo"

    def text(self) -> str:
        return f"fifo:{self.period * 1e3:g}ms"

    def start(self, rng: np.random.Generator) -> Transform:
        return _Fifo(self)


class _Fifo(Transform):
    MIN_STEP_NS = 10_000

    def __init__(self, p: Fifo) -> None:
        self.period_ns = round(p.period * 1e9)
        self.t0: int | None = None  # the first read (the sequence's first stamp)
        self.last: int | None = None  # the previous output stamp (ns)
        self.last_read: int | None = None
        self.samples = 0
        self.reads = 0

    def __call__(self, rec: Recording) -> Recording:
        n = len(rec)
        if n == 0:
            return rec
        if self.t0 is None:
            self.t0 = int(rec.stamps_ns[0])
        p = self.period_ns
        read = self.t0 + -((self.t0 - rec.stamps_ns) // p) * p  # ceil to the read grid
        self.reads += len(np.unique(read)) - int(read[0] == self.last_read)  # a read split across chunks: once
        self.last_read = int(read[-1])
        out = _in_order(read, self.last, self.MIN_STEP_NS)
        self.last = int(out[-1])
        self.samples += n
        return _with(rec, stamps_ns=out)

    def info(self) -> dict[str, Any]:
        return {"samples": self.samples, "reads": self.reads}


# ---------------------------------------------------------------------------------------------------
# dropouts
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Dropout(Perturbation):
    """Holes of ``lo``–``hi`` s about every ``every`` s (exponential spacing), starting at a scored sample."""

    lo: float = 0.1
    hi: float = 0.6
    every: float = 10.0
    kind = "dropout"

    def text(self) -> str:
        return f"dropout:{self.lo:g}-{self.hi:g}s@{self.every:g}s"

    def start(self, rng: np.random.Generator) -> Transform:
        return _Holes(self, rng)


class _Holes(Transform):
    def __init__(self, p: Dropout, rng: np.random.Generator) -> None:
        self.p = p
        self.rng = rng
        self.candidate: int | None = None  # earliest start of the next hole (ns)
        self.hole: tuple[int, int] | None = None  # current hole [start, end)
        self.holes = 0
        self.removed = 0

    def _next_candidate(self, after: int) -> None:
        self.candidate = after + round(self.rng.exponential(self.p.every) * 1e9)

    def __call__(self, rec: Recording) -> Recording:
        st = rec.stamps_ns
        if self.candidate is None:
            self._next_candidate(int(st[0]))
        keep = np.ones(len(st), dtype=bool)
        while True:
            if self.hole is not None:
                a, b = self.hole
                keep &= ~((st >= a) & (st < b))
                if b > st[-1]:
                    break  # the hole goes on into the next piece
                self.hole = None
                self._next_candidate(b)
            at = np.flatnonzero((st >= self.candidate) & rec.score_mask)  # type: ignore[operator]
            if not len(at):
                break  # no scored sample after the candidate in this piece: wait for the next
            start = int(st[at[0]])
            self.hole = (start, start + round(self.rng.uniform(self.p.lo, self.p.hi) * 1e9))
            self.holes += 1
        self.removed += int((~keep).sum())
        return rec if keep.all() else _with(rec, keep)

    def info(self) -> dict[str, Any]:
        return {"holes": self.holes, "samples_removed": self.removed}


# ---------------------------------------------------------------------------------------------------
# conditions
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Condition:
    """Perturbations applied in order; the empty condition is ``none``."""

    parts: tuple[Perturbation, ...] = ()

    @property
    def label(self) -> str:
        return "+".join(p.text() for p in self.parts) or NONE

    def nominal_rate(self, rate_hz: float) -> float:
        for p in self.parts:
            rate_hz = p.nominal_rate(rate_hz)
        return rate_hz

    def start(self, rngs: list[np.random.Generator]) -> list[Transform]:
        return [p.start(rng) for p, rng in zip(self.parts, rngs, strict=True)]


_NUM = r"[0-9]*\.?[0-9]+(?:e[-+]?[0-9]+)?"


def _seconds(text: str, unit: str) -> float:
    return float(text) * (1e-3 if unit == "ms" else 1.0)


def _points(parse: Callable[[str], Perturbation | None]) -> Callable[[str], Perturbation | None]:
    """``parse`` that also takes a ``:points`` suffix (jitter and rate: the signal at the stamps)."""

    def wrapped(args: str) -> Perturbation | None:
        base, sep, tail = args.rpartition(":")
        if sep and tail == "points":
            p = parse(base)
            return replace(p, points=True) if isinstance(p, Jitter) else None
        return parse(args)

    return wrapped


def _jitter(args: str) -> Perturbation | None:
    m = re.fullmatch(rf"({_NUM}(?:/{_NUM})*)(ms|s)", args)
    if m:
        vals = tuple(_seconds(v, m.group(2)) for v in m.group(1).split("/"))
        return Jitter(choices=vals) if all(v > 0 for v in vals) else None
    m = re.fullmatch(rf"({_NUM})-({_NUM})(ms|s)", args)
    if m:
        lo, hi = _seconds(m.group(1), m.group(3)), _seconds(m.group(2), m.group(3))
        return Jitter(lo=lo, hi=hi) if 0 < lo <= hi else None
    return None


def _rate(args: str) -> Perturbation | None:
    m = re.fullmatch(rf"({_NUM})(?:hz)?", args)
    return Rate(hz=float(m.group(1))) if m and float(m.group(1)) > 0 else None


def _bias(args: str) -> Perturbation | None:
    m = re.fullmatch(rf"random:({_NUM})", args)
    if m:
        return Bias(sigma=float(m.group(1)))
    m = re.fullmatch(rf"(-?{_NUM}),(-?{_NUM}),(-?{_NUM})", args)
    return Bias(dps=(float(m.group(1)), float(m.group(2)), float(m.group(3)))) if m else None


def _latency(args: str) -> Perturbation | None:
    m = re.fullmatch(rf"({_NUM})-({_NUM})(ms|s)", args)
    if not m:
        return None
    lo, hi = _seconds(m.group(1), m.group(3)), _seconds(m.group(2), m.group(3))
    return Latency(lo, hi) if 0 <= lo <= hi else None


def _fifo(args: str) -> Perturbation | None:
    m = re.fullmatch(rf"({_NUM})(ms|s)", args)
    if not m:
        return None
    period = _seconds(m.group(1), m.group(2))
    return Fifo(period) if period > 0 else None


def _dropout(args: str) -> Perturbation | None:
    m = re.fullmatch(rf"({_NUM})-({_NUM})s@({_NUM})s", args)
    if not m:
        return None
    lo, hi, every = (float(v) for v in m.groups())
    return Dropout(lo, hi, every) if 0 < lo <= hi and every > 0 else None


def _magnetic(args: str) -> Perturbation | None:
    m = re.fullmatch(rf"offset:(-?{_NUM}),(-?{_NUM}),(-?{_NUM})", args)
    if m:
        return Magnetic(offset=(float(m.group(1)), float(m.group(2)), float(m.group(3))))
    m = re.fullmatch(rf"disturb:({_NUM})(?:ut)?@({_NUM})-({_NUM})s", args)
    if not m:
        return None
    strength, t0, t1 = (float(v) for v in m.groups())
    return Magnetic(strength=strength, t0=t0, t1=t1) if t0 < t1 else None


_PARSERS = {"jitter": _points(_jitter), "rate": _points(_rate), "latency": _latency, "fifo": _fifo, "bias": _bias,
            "dropout": _dropout, "magnetic": _magnetic}


def parse_perturbation(text: str) -> Perturbation:
    """One ``kind:args`` item (see the module docstring); ``ValueError`` with the accepted forms."""
    kind, _, args = text.strip().lower().replace(" ", "").partition(":")
    parser = _PARSERS.get(kind)
    p = parser(args) if parser else None
    if p is None:
        raise ValueError(
            f"bad perturbation {text!r}; accepted: jitter:10/20/30ms, jitter:8-32ms, rate:50 (each also with :points), "
            "latency:0-20ms, "
            "fifo:20ms, bias:3,3,0, bias:random:2 (deg/s), dropout:0.1-0.6s@10s, magnetic:offset:20,0,-10 (µT), "
            "magnetic:disturb:40@10-20s"
        )
    return p


def parse_condition(text: str) -> Condition:
    """``none`` or perturbations joined with ``+`` (``jitter:10/20/30ms+bias:3,3,0``)."""
    t = text.strip()
    if not t or t.lower() == NONE:
        return Condition()
    return Condition(tuple(parse_perturbation(p) for p in t.split("+")))

