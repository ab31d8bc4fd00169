"""The magnetometer's lag, scanned over the whole range a reading may be paired at: up to ``mag_timeout`` (ROS-free).

The latency fit (:mod:`.latency`) is first order in the lag and bounded to :data:`~.latency.MAX_DELAY` (0.1 s): it
sees a few tens of ms well, and a reading 300 ms late not at all (a slow driver that stamps a field of 300 ms ago
with the current time: the heading is then off by the rotation of the last 300 ms, 60° at 200 °/s). This scan sees
any lag up to ``mag_timeout``, exactly: a field fixed in the world satisfies ``R(t₀ − τ) m₀ = R(t₁ − τ) m₁`` for the
readings ``m₀``, ``m₁`` taken ``τ`` before their stamps ``t₀``, ``t₁`` and the gyro's attitude ``R``. Over windows of
:data:`WINDOW_S` with at least :data:`MIN_TURN_DEG` of rotation, each lag of a grid (:data:`STEP_S`) gets the residual
``|m₁ − R(t₁ − τ)ᵀ R(t₀ − τ) m₀|² / |m₀|²``, summed with forgetting (:data:`TAU_S`). The lag with the least sum is the
estimate; the field is *late* when that lag, after :data:`MIN_WINDOWS` windows, is beyond a range ``covered``
(:meth:`LagScan.late`; the front end asks beyond the scan's resolution, :data:`RESOLUTION_S`: the latency fit sees up to
:data:`~.latency.MAX_DELAY` but to first order) and its residual is below :data:`CLEAR` times the least residual
within that range. The front end then rotates the field back over the scanned lag (the gyro's rotation over it,
exact) for every estimator, and the calibration's windows take their ends there; the magnetometer's monitor warns.
A hard iron left in the field adds the same kind of term to every lag's residual, so it blurs the minimum without
moving it much; the front end scans the field through the configured (or saved) calibration, so that an online
estimate taken at a wrong lag cannot blur it.

Until the scan has resolved the lag the field's timing is unknown within 0 … ``max_lag_s``, and a field read ``τ``
late turns the heading by the rotation about the vertical over ``τ``: ``|ω_v| · max_lag_s / √3`` (``τ`` uniform over
the range; 0 at rest, where a lag does nothing). A heading filter keeps what such a field taught it for about its
field time constant, so the doubt (:attr:`LagScan.doubt_sd`, which the heading's σ carries) is the largest of these
since, decaying with :data:`DOUBT_TAU_S`, also after the scan has resolved the lag and the compensation begins.
"""

from __future__ import annotations

import bisect
import math

from riann_ros.magcal.latency import MAX_DELAY
from riann_ros.rotations import IDENTITY, Quat, Vec, normalized, qmul, rotate

#: s; the window between two readings compared
WINDOW_S = 0.25
#: deg; a window must turn at least this much (less tells no lag apart)
MIN_TURN_DEG = 10.0
#: s; the grid of lags
STEP_S = 0.01
#: s; the windows' sums are forgotten with this time constant (a driver's lag is a property of the driver)
TAU_S = 30.0
#: windows before the scan says anything
MIN_WINDOWS = 8
#: the scanned lag's residual must be below this share of the least residual within the range compensated otherwise
CLEAR = 0.5
#: s; a lag the scan tells from none: three steps of its grid (the sensor's own latency, BROAD's 10 ms, is not one)
RESOLUTION_S = 3 * STEP_S
#: s; the heading filters' field time constant (VQF's tauMag 9 s; RIANN's heading stage corrects over seconds): how
#: long a heading keeps what a field of unknown timing taught it
DOUBT_TAU_S = 10.0
_COS_MIN_TURN = math.cos(math.radians(MIN_TURN_DEG) / 2.0)


class LagScan:
    """The scan (module docstring) over lags 0 … ``max_lag_s``; :meth:`add` per sample."""

    def __init__(self, max_lag_s: float) -> None:
        self.lags = [k * STEP_S for k in range(int(max_lag_s / STEP_S + 1e-9) + 1)]
        self.reset()

    def reset(self) -> None:
        self.t = 0.0  # s, this scan's clock (the sum of the samples' steps)
        self.q: Quat = IDENTITY  # the gyro's attitude at t (sensor → a frame fixed at the start)
        self._ts: list[float] = [0.0]  # the attitude history: times and attitudes
        self._qs: list[Quat] = [IDENTITY]
        self._open: tuple[float, Vec] | None = None  # the open window's first reading: (t, m)
        self.sums = [0.0] * len(self.lags)
        self.windows = 0.0  # forgotten count
        self.lag_s: float | None = None  # the lag of the least sum (None: too few windows)
        self.doubt_sd = 0.0  # rad; the heading's doubt from the field's unknown timing (track_doubt)
        self._late: dict[float, float | None] = {}  # late_s per range, since the last window

    def add(self, delta: Quat, dt: float, mag: Vec | None) -> None:
        """One sample: its gyro increment over ``dt`` s, its field (any unit; None: none)."""
        self.t += dt
        self.q = normalized(qmul(self.q, delta))
        self._ts.append(self.t)
        self._qs.append(self.q)
        keep = self.t - self.lags[-1] - 2.0 * WINDOW_S
        if self._ts[0] < keep - 1.0:  # trim now and then (amortised)
            k = bisect.bisect_left(self._ts, keep)
            del self._ts[:k], self._qs[:k]
        if mag is None:
            return
        if self._open is None or self.t - self._open[0] > 2.0 * WINDOW_S:
            self._open = (self.t, mag)
            return
        if self.t - self._open[0] >= WINDOW_S:
            t0, m0 = self._open
            self._open = (self.t, mag)
            self._window(t0, m0, self.t, mag)

    def _at(self, t: float) -> Quat:
        """The gyro's attitude at ``t`` (the newest sample at or before it)."""
        k = bisect.bisect_right(self._ts, t) - 1
        return self._qs[max(k, 0)]

    def _window(self, t0: float, m0: Vec, t1: float, m1: Vec) -> None:
        q0, q1 = self._at(t0), self._at(t1)
        turn = q0[0] * q1[0] + q0[1] * q1[1] + q0[2] * q1[2] + q0[3] * q1[3]
        n0 = m0[0] * m0[0] + m0[1] * m0[1] + m0[2] * m0[2]
        if abs(turn) > _COS_MIN_TURN or not n0 > 0.0 or t0 - self.lags[-1] < self._ts[0]:
            return
        f = math.exp(-(t1 - t0) / TAU_S)
        for k, lag in enumerate(self.lags):
            a, b = self._at(t0 - lag), self._at(t1 - lag)
            w = rotate(a, m0)  # the world field the first reading says
            p = rotate((b[0], -b[1], -b[2], -b[3]), w)  # … seen at the second
            e = (m1[0] - p[0], m1[1] - p[1], m1[2] - p[2])
            self.sums[k] = f * self.sums[k] + (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]) / n0
        self.windows = f * self.windows + 1.0
        if self.windows >= MIN_WINDOWS:
            k = min(range(len(self.lags)), key=self.sums.__getitem__)
            self.lag_s = self.lags[k]
        self._late = {}

    def track_doubt(self, q: Quat | None, rv: Vec, dt: float) -> None:
        """Once per sample, after :meth:`add`: the heading's doubt from the field's unknown timing at the attitude
        ``q`` (sensor → world; None: not yet known, the sensor's z taken as up), the sample's rotation vector ``rv``
        over ``dt`` s, while the scan has not resolved the lag, kept as the largest since, decaying with
        :data:`DOUBT_TAU_S` (module docstring)."""
        now = 0.0
        if self.lag_s is None and dt > 0.0:
            up = (0.0, 0.0, 1.0) if q is None else rotate((q[0], -q[1], -q[2], -q[3]), (0.0, 0.0, 1.0))
            w_v = (rv[0] * up[0] + rv[1] * up[1] + rv[2] * up[2]) / dt
            now = min(abs(w_v) * self.lags[-1] / math.sqrt(3.0), 0.5 * math.pi)
        self.doubt_sd = max(now, self.doubt_sd * math.exp(-dt / DOUBT_TAU_S))

    @property
    def late_s(self) -> float | None:
        """s; the scanned lag when the field is late beyond the latency fit's range (:data:`~.latency.MAX_DELAY`),
        else None."""
        return self.late(MAX_DELAY)

    def late(self, covered_s: float) -> float | None:
        """s; the scanned lag when it is beyond ``covered_s`` (what the estimator compensates itself) and clearly
        (its residual below :data:`CLEAR` times the least residual within ``covered_s``), else None."""
        if covered_s not in self._late:
            self._late[covered_s] = self._beyond(covered_s)
        return self._late[covered_s]

    def _beyond(self, covered_s: float) -> float | None:
        lag = self.lag_s
        if lag is None or lag <= covered_s + 0.5 * STEP_S:
            return None
        near = min(s for s, x in zip(self.sums, self.lags, strict=True) if x <= covered_s + 0.5 * STEP_S)
        return lag if self.sums[self.lags.index(lag)] < CLEAR * near else None

    def compensated(self, m: Vec, lag_s: float) -> Vec:
        """The field ``m`` read ``lag_s`` before the current sample, as the sensor sees it now: rotated by the gyro's
        turn over the lag."""
        a = self._at(self.t - lag_s)
        w = rotate(a, m)
        q = self.q
        return rotate((q[0], -q[1], -q[2], -q[3]), w)
