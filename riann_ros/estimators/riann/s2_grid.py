"""Stage 2, the grid: the input samples resampled causally onto the network's constant-step grid (ROS-free).

The network runs on grid points ``tau_m = anchor + m·T`` (``T`` and how to read the samples from stage 1). The
recent samples are held as a signal over time (:class:`SignalHistory`): piecewise linear through point samples,
or piecewise constant over ``(t_{k-1}, t_k]`` for interval means; up-sampled point samples are read *curved*
(the parabola through the newest three samples: at 25–50 Hz a line cuts the corners of fast rotations). A grid
point becomes a row as soon as the samples cover its window, from the samples up to that stamp only: the
resampling is causal. A grid value is the signal at the grid point, or its mean over the box width: up-sampled
(point samples or interval means), the cell *centred* on the grid point (the network reads a row as the signal at
its time, as it reads a sample fed straight in; a cell ending there, or the interval mean holding the grid point,
would make the rows half a cell late on average); for blocks the width before it.
Each sample also gets the raw gyro means the carry stage (5) turns into rotations. After a hole the grid goes on
across it (the rows in the hole are interpolated: the *bridge*) and marks where a fresh network starts.

:class:`DirectRows` is the grid's stand-in with ``rate_adaptation`` off: every sample is one row with its own dt.
docs/riann.md, stage 2.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence

from riann_ros.estimators.riann.s1a_rate import REL_EPS
from riann_ros.estimators.riann.stage import ZERO3, Cause, GridBlock, GridSpec, Row6, Samples, TimelineBlock, Vec

TIME_EPS_NS = 1000.0  # a grid point this close after the newest stamp counts as reached (1 µs)
CURVE_MIN_RATIO = 0.5  # the curved signal model needs neighbouring sample steps less than 2x apart

Sample = Sequence[float]


class _Rows:
    """The lists of one block's :class:`~.stage.GridBlock`, filled sample by sample."""

    def __init__(self) -> None:
        self.rows: list[Row6] = []
        self.row_step_s: list[float] = []
        self.forks: list[int] = []
        self.r0: list[int] = []
        self.r1: list[int] = []
        self.gyr_delta: list[Vec] = []
        self.delta_s: list[float] = []
        self.gyr_carry: list[Vec] = []
        self.carry_s: list[float] = []

    def block(self, tl: TimelineBlock) -> GridBlock:
        return GridBlock(self.rows, self.row_step_s, self.forks, self.r0, self.r1, self.gyr_delta, self.delta_s,
                         self.gyr_carry, self.carry_s, tl.holes)


class Grid:
    """Stage 2 (see the module docstring)."""

    NAME = "grid"

    def __init__(self) -> None:
        self.restart(Cause.RESET)

    def restart(self, cause: Cause) -> None:
        """GAP and RESET alike: the next sample starts a new grid (holes are bridged in run)."""
        self.hist = SignalHistory()
        self._anchor = 0.0  # ns; grid point m is at anchor + m * T
        self._m = 0
        self._t_net = 0.0  # ns of the last grid point made a row
        self._t = 0.0  # ns of the newest sample's stamp
        self._s = 0.0  # ns of its signal time (the stamp less the sample delay)
        self._w: Sample = ZERO3  # its raw gyro

    def run(self, block: TimelineBlock) -> GridBlock:
        out = _Rows()
        holes = {h.sample for h in block.holes}
        for k, xk in enumerate(block.samples.x):
            self._sample(out, xk, block.t_ns[k], block.spec[k], block.start[k], block.switched[k])
            if k in holes:
                out.forks.append(len(out.rows))
        return out.block(block)

    def _sample(self, out: _Rows, xk: Row6, t: float, spec: GridSpec, start: bool, switched: bool) -> None:
        """One sample at time ``t`` (ns): its rows, its gyro step from the previous sample and its carry."""
        hist = self.hist
        T, width, means = spec.step_s, spec.box_s, spec.means
        if start:
            s = t - spec.delay_s * 1e9
            self._anchor = s - T * 1e9  # the first grid point on the first sample's signal time
            self._m = 0
            self._t_net = self._anchor
            t_prev = s_prev = t
            w_prev: Sample = (xk[3], xk[4], xk[5])
        else:
            t_prev, s_prev, w_prev = self._t, self._s, self._w
            s = max(t - spec.delay_s * 1e9, s_prev)  # the signal time never runs backwards (a larger delay)
            if switched:
                self._anchor = self._t_net
                self._m = 0
        self._t, self._s, self._w = t, s, (xk[3], xk[4], xk[5])
        hist.append(s, xk)
        if t > t_prev:
            out.gyr_delta.append(self._delta(t - t_prev, s_prev, s, t_prev - s_prev, t - s, w_prev, means))
            out.delta_s.append((t - t_prev) * 1e-9)
        else:
            out.gyr_delta.append(ZERO3)
            out.delta_s.append(0.0)
        out.r0.append(len(out.rows))
        self._emit(out, s, T, width, means, spec.upsampled, start)
        out.r1.append(len(out.rows))
        if t > self._t_net + TIME_EPS_NS:  # the newest row carried to the stamp (beyond s the newest gyro held)
            out.gyr_carry.append(_vec(hist.mean(self._t_net, t, means, 3, 6)))
            out.carry_s.append((t - self._t_net) * 1e-9)
        else:
            out.gyr_carry.append(ZERO3)
            out.carry_s.append(0.0)
        hist.trim(self._t_net - max(width * 1e9, T * 1e9) - 1.0)

    def _delta(self, span: float, s_prev: float, s: float, d_prev: float, d: float, w_prev: Sample,
               means: bool) -> Vec:
        """Mean gyro from the previous sample's stamp to this one's (``span`` ns): the outputs there are the signal
        at ``s_prev`` and ``s`` carried on by the gyro held over the delays ``d_prev`` and ``d``, so the step is
        the signal from ``s_prev`` to ``s`` less the previous carry plus this one (the steps add up exactly)."""
        g = self.hist.mean(s_prev, s, means, 3, 6) if s > s_prev else [0.0, 0.0, 0.0]
        if d == 0.0 and d_prev == 0.0:
            return g[0], g[1], g[2]
        w = self._w
        a = (s - s_prev) / span
        return (a * g[0] + (w[0] * d - w_prev[0] * d_prev) / span, a * g[1] + (w[1] * d - w_prev[1] * d_prev) / span,
                a * g[2] + (w[2] * d - w_prev[2] * d_prev) / span)

    def _emit(self, out: _Rows, t: float, T: float, width: float, means: bool, up: bool,
              first: bool = False) -> None:
        """Append every grid row whose window ends by the newest signal time ``t`` (on a stream's ``first`` sample
        its first row, the signal held before and after that sample)."""
        T_ns = T * 1e9
        w_ns = width * 1e9
        half = 0.5 * w_ns if up else 0.0  # up-sampled: the cell centred on the grid point
        curved = up and not means  # up-sampled point samples: the parabola through the newest three
        hist = self.hist
        while True:
            tau = self._anchor + (self._m + 1) * T_ns
            if tau + half > t + TIME_EPS_NS and not (first and self._m == 0):
                return
            if w_ns > 0.0:
                v = hist.mean(tau + half - w_ns, tau + half, means, curved=curved)
            else:
                v = hist.value(tau, means)
            out.rows.append(v)
            out.row_step_s.append(T)
            self._m += 1
            self._t_net = tau

    def diagnostics(self) -> dict[str, str]:
        return {}


def _vec(v: list[float]) -> Vec:
    return v[0], v[1], v[2]


class DirectRows:
    """``rate_adaptation`` off: every sample is one network row with its own dt (no grid, no holes). It stands in
    for stages 1 and 2 and takes the samples themselves."""

    NAME = "grid"

    def restart(self, cause: Cause) -> None:
        pass

    def run(self, block: Samples) -> GridBlock:
        x, dt = block.x, block.dt_s
        n = len(x)
        idx = list(range(n))
        return GridBlock(rows=x, row_step_s=dt, forks=[], r0=idx, r1=[i + 1 for i in idx],
                         gyr_delta_rad_s=[(r[3], r[4], r[5]) for r in x], delta_s=dt,
                         gyr_carry_rad_s=[ZERO3] * n, carry_s=[0.0] * n, holes=[])

    def diagnostics(self) -> dict[str, str]:
        return {}


class SignalHistory:
    """Recent samples ``(t, x)`` (t in ns as float, x a 6-vector) read as a continuous signal.

    ``means=False``: linear between samples; ``means=True``: sample k holds over ``(t_{k-1}, t_k]``.
    Before the first sample the signal holds the first value, after the last the last one.
    """

    def __init__(self) -> None:
        self.t: deque[float] = deque()
        self.x: deque[Sample] = deque()

    def __len__(self) -> int:
        return len(self.t)

    def append(self, t: float, x: Sample) -> None:
        self.t.append(t)
        self.x.append(x)

    def clear(self) -> None:
        self.t.clear()
        self.x.clear()

    def trim(self, before: float) -> None:
        """Drop samples no window starting at ``before`` or later can need (keeps two before it: the
        curved model of the interval around ``before`` reads the sample before that interval)."""
        t = self.t
        while len(t) > 3 and t[2] <= before:
            t.popleft()
            self.x.popleft()

    def value(self, tau: float, means: bool) -> list[float]:
        """The signal at ``tau``."""
        t, x = self.t, self.x
        n = len(t)
        k = n - 1
        while k > 0 and t[k - 1] >= tau:  # k = first sample at or after tau (or the last)
            k -= 1
        if means or k == 0 or t[k] <= tau:
            return list(x[k])
        t0, t1 = t[k - 1], t[k]
        s = (tau - t0) / (t1 - t0)
        return [a + s * (b - a) for a, b in zip(x[k - 1], x[k], strict=True)]

    def mean(self, a: float, b: float, means: bool, lo: int = 0, hi: int = 6, curved: bool = False) -> list[float]:
        """Mean of channels ``lo:hi`` over ``(a, b]``; the value at ``b`` when the window is empty (``b <= a``,
        e.g. a width that rounds away next to a stamp in ns)."""
        if not b > a:
            return self.value(b, means)[lo:hi]
        t, x = self.t, self.x
        acc = [0.0] * (hi - lo)
        if a < t[0]:  # before the first sample: its value held
            _add(acc, x[0], lo, min(b, t[0]) - a)
        for k in range(len(t) - 1, 0, -1):
            if t[k] <= a:
                break
            self._add_interval(acc, k, a, b, means, lo, curved)
        if b > t[-1]:  # after the last sample: its value held
            _add(acc, x[-1], lo, b - max(a, t[-1]))
        w = b - a
        return [v / w for v in acc]

    def _add_interval(self, acc: list[float], k: int, a: float, b: float, means: bool, lo: int,
                      curved: bool = False) -> None:
        """Add the integral over ``(a, b] ∩ (t_{k-1}, t_k]`` of the signal model to ``acc``. ``curved``: point
        samples as the parabola through samples k-2, k-1, k (causal: k is the newest sample the interval
        needs) instead of the line through k-1, k, where the three are about evenly spaced."""
        t0, t1 = self.t[k - 1], self.t[k]
        s0, s1 = max(a, t0), min(b, t1)
        if s1 <= s0:
            return
        x0, x1 = self.x[k - 1], self.x[k]
        span = s1 - s0
        if means:
            _add(acc, x1, lo, span)
            return
        h1 = t1 - t0
        m = 0.5 * ((s0 - t0) + (s1 - t0)) / h1
        for j in range(len(acc)):
            acc[j] += (x0[lo + j] + m * (x1[lo + j] - x0[lo + j])) * span
        if not curved or k < 2:
            return
        h0 = t0 - self.t[k - 2]
        lo_ratio = CURVE_MIN_RATIO * (1.0 + REL_EPS)  # a margin: steps exactly 2x apart (10/20 ms) must not
        if not lo_ratio * h1 < h0 < h1 / lo_ratio:  # flip with the rounding of a stamp sum (chunked = whole)
            return  # across a hole or a rate change: no curvature to read
        # p(u) = line + c·u·(u − h1), u = t − t_{k-1}, c fixed by p(−h0) = x_{k-2}
        u0, u1 = s0 - t0, s1 - t0
        w = ((u1**3 - u0**3) / 3.0 - 0.5 * h1 * (u1**2 - u0**2)) / (h0 * (h0 + h1))
        xm = self.x[k - 2]
        for j in range(len(acc)):
            acc[j] += w * (xm[lo + j] - x0[lo + j] + (x1[lo + j] - x0[lo + j]) * h0 / h1)


def _add(acc: list[float], x: Sample, lo: int, span: float) -> None:
    for j in range(len(acc)):
        acc[j] += x[lo + j] * span
