"""Perturbations of the stamps (ROS-free): irregular stamps with interval means or point samples (``jitter:``),
a regular stream at another rate (``rate:``: interval means, point samples or a low-pass sensor's samples),
receive-time stamps (``latency:``) and FIFO read-out (``fifo:``).
Definitions: :data:`~riann_ros.evaluation.perturb.conditions.DEFINITIONS`."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from riann_ros import quaternion as quat
from riann_ros.constants import NS_PER_S
from riann_ros.evaluation.perturb.base import DRAW_BLOCK, Perturbation, Transform, concat, in_order, with_samples
from riann_ros.recording import Recording


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
            ns = np.round(np.asarray(self.choices) * NS_PER_S).astype(np.int64)
            return lambda: rng.choice(ns, DRAW_BLOCK)
        lo, hi = round(self.lo * NS_PER_S), round(self.hi * NS_PER_S)
        return lambda: rng.integers(lo, hi, DRAW_BLOCK, endpoint=True)

    def start(self, rng: np.random.Generator) -> Transform:
        return _IntervalMeans(self.draw(rng), self.points)


@dataclass(frozen=True)
class Rate(Jitter):
    """A regular stream at ``hz``; ``lowpass``: each sample the signal at its stamp after a first-order low-pass
    of time constant half a step (a MEMS sensor's anti-alias filter, stamped at data-ready)."""

    hz: float = 100.0
    lowpass: bool = False
    kind = "rate"

    def text(self) -> str:
        return f"rate:{self.hz:g}" + (":lowpass" if self.lowpass else self._suffix())

    def start(self, rng: np.random.Generator) -> Transform:
        return _IntervalMeans(self.draw(rng), self.points, 0.5 / self.hz if self.lowpass else 0.0)

    def mean_interval(self) -> float:
        return 1.0 / self.hz

    def draw(self, rng: np.random.Generator) -> Callable[[], NDArray[np.int64]]:
        # exact ns grid (1/3 ms steps alternate 333333 and 333334 ns): stamps k * 1e9 / hz, rounded
        step = NS_PER_S / self.hz
        state = {"k": 0}

        def block() -> NDArray[np.int64]:
            k = state["k"] + np.arange(DRAW_BLOCK + 1)
            state["k"] += DRAW_BLOCK
            return np.diff(np.round(k * step)).astype(np.int64)

        return block


class _IntervalMeans(Transform):
    """New stamps t_k = t_{k-1} + interval; sample k = mean of the signal over (t_{k-1}, t_k] (``points``: the
    signal at t_k; ``tau`` > 0: the signal low-passed with that time constant (s), at t_k)."""

    def __init__(self, draw: Callable[[], NDArray[np.int64]], points: bool = False, tau: float = 0.0) -> None:
        self._draw = draw
        self._points = points
        self._tau = tau
        self._queue = np.zeros(0, np.int64)
        self._tail: Recording | None = None  # the samples needed again: from the last at or before t_prev
        self._y: NDArray[np.float64] | None = None  # the low-passed signal at the tail's samples (tau > 0)
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
        buf = rec if self._tail is None else concat(self._tail, rec)
        y = self._lowpass(buf, rec) if self._tau > 0.0 else None
        times = self._times(self._t_prev, int(buf.stamps_ns[-1]))
        edges = np.concatenate([[self._t_prev], times])
        out = _interval_means(buf, edges, self._points, y, self._tau) if len(times) else None
        if len(times):
            self._t_prev = int(times[-1])
        keep_from = max(0, int(np.searchsorted(buf.stamps_ns, self._t_prev, side="right")) - 1)
        self._tail = buf.slice(keep_from)
        self._y = None if y is None else y[keep_from:]
        parts = [p for p in (first, out) if p is not None]
        result = concat(*parts) if len(parts) > 1 else (parts[0] if parts else rec.slice(0, 0))
        self.emitted += len(result)
        return result

    def _lowpass(self, buf: Recording, rec: Recording) -> NDArray[np.float64]:
        """The low-passed signal at ``buf``'s samples: the tail's kept, ``rec``'s continued from it (exact for
        the piecewise-linear signal; the filter starts settled on the first sample)."""
        x = np.concatenate([buf.acc, buf.gyr], axis=1)
        t = buf.stamps_ns * 1e-9
        y = np.empty_like(x)
        n0 = len(buf) - len(rec)
        if self._y is None or n0 == 0:
            y[0] = x[0]
            n0 = 1
        else:
            y[:n0] = self._y
        tau = self._tau
        for i in range(n0, len(x)):
            h = t[i] - t[i - 1]
            st = (x[i] - x[i - 1]) * (tau / h) if h > 0.0 else np.zeros(6)
            y[i] = x[i] - st + (y[i - 1] - x[i - 1] + st) * np.exp(-h / tau)
        return y

    def info(self) -> dict[str, Any]:
        return {"samples": self.emitted}


def _interval_means(buf: Recording, edges: NDArray[np.int64], points: bool = False,
                    y: NDArray[np.float64] | None = None, tau: float = 0.0) -> Recording:
    """Samples at ``edges[1:]``: means of acc and gyr (piecewise linear between ``buf``'s samples) over each
    (edges[k-1], edges[k]] (``points``: their values at the edge; ``y``: the signal low-passed with time constant
    ``tau``, ``y`` at ``buf``'s samples, at the edge); reference slerped at the edge, score mask of the nearest
    sample, magnetic field of the latest sample at or before the edge (a magnetometer read when the sample is
    made)."""
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
    if y is not None and len(t) > 1:  # the first-order filter's response to the line through the segment
        st = slope * tau
        means = (x[i] + slope * d[:, None] - st + (y[i] - x[i] + st) * np.exp(-d / tau)[:, None])[1:]
    elif not points:
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
    return with_samples(buf, None, stamps_ns=edges[1:], acc=means[:, :3], gyr=means[:, 3:],
                        quat_ref=ref, score_mask=buf.score_mask[nearest[1:]], mag=mag)


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
        delay = np.round(self.rng.uniform(self.p.lo, self.p.hi, n) * NS_PER_S).astype(np.int64)
        out = in_order(rec.stamps_ns + delay, self.last, self.MIN_STEP_NS)
        self.last = int(out[-1])
        self.samples += n
        return with_samples(rec, stamps_ns=out)

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
        self.period_ns = round(p.period * NS_PER_S)
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
        out = in_order(read, self.last, self.MIN_STEP_NS)
        self.last = int(out[-1])
        self.samples += n
        return with_samples(rec, stamps_ns=out)

    def info(self) -> dict[str, Any]:
        return {"samples": self.samples, "reads": self.reads}
