"""The consensus's two opinions at one instant: how far VQF on RIANN's rows lags RIANN, fitted online (ROS-free).

A weighted mean of two attitudes is only as good as the instant they share: one that lags the other by τ while the
sensor turns at ω errs by about ωτ against it, whatever their weights. RIANN's output and VQF's attitude need not
refer to the same instant. RIANN's network learned its timing from its training data (on BROAD, as recorded, it is
on time within 0.3 ms: ``best_t_offset_s`` of docs/results/perturbed.json), while VQF's strapdown integration turns
by each row's gyro over the whole step (the rectangle rule) and corrects toward the accelerometer as its samples
come, so its instant depends on the sample convention (point samples or interval means) and on the sensor's own
filter delay. On BROAD 07 as recorded VQF on RIANN's rows lags RIANN by 2.5 ms; at 300 °/s that is 0.8°
(``bench/consensus_timing.py``).

The lag is read from the two opinions themselves: while the sensor turns, a gravity direction (sensor frame) moves
as ``ġ = g × ω``, so VQF's opinion as RIANN's of ``τ`` earlier differs from it by ``g_V − g_R ≈ −τ (g_R × ω)``. The
least-squares ``τ`` over the recent past (both sums low-passed over :data:`LAG_TAUS` × VQF's ``τ_acc``, so VQF's own
slow errors, which do not follow the turn, average out) moves VQF's attitude on by the gyro over ``τ`` before the two
are combined: the output keeps RIANN's instant, the timing the node has always published (docs/riann.md, stage 1).
Bounded by :data:`MAX_LAG_S`; 0 until the turns inform it (:data:`MIN_TURN_RAD2_S2`).
"""

from __future__ import annotations

import math

from riann_ros.rotations import Quat, Vec, from_rotvec, qmul

#: the lag's sums average over this many of VQF's time constants (VQF's own errors correlate over about one)
LAG_TAUS = 10.0
#: s; the lag is kept within this (a sample convention and a sensor filter's delay make a few ms to a step)
MAX_LAG_S = 0.05
#: rad²/s²; the mean squared turn rate (of the gravity direction) below which the lag is not fitted: 6 °/s RMS
MIN_TURN_RAD2_S2 = (6.0 * math.pi / 180.0) ** 2


class RelativeLag:
    """How far VQF's opinion lags RIANN's (module docstring): :meth:`step` per sample, :meth:`move` VQF's
    attitude to RIANN's instant."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Forget the lag (a reset: perhaps another sensor; a gap keeps it: the same sensor)."""
        self._s_dt = 0.0  # low-passed (g_V − g_R)·(g_R × ω)
        self._s_tt = 0.0  # low-passed |g_R × ω|²
        self.tau_s = 0.0

    def step(self, gr: Vec, gv: Vec, w: Vec, dt: float, horizon_s: float) -> float:
        """One sample: RIANN's and VQF's gravity directions ``gr``, ``gv`` (sensor frame, VQF's not yet moved), the
        bias-corrected gyro ``w`` (rad/s), ``dt`` s since the previous sample, the averaging ``horizon_s``; the lag
        (s) fitted so far."""
        tx, ty, tz = gr[1] * w[2] - gr[2] * w[1], gr[2] * w[0] - gr[0] * w[2], gr[0] * w[1] - gr[1] * w[0]
        k = min(dt / horizon_s, 1.0) if horizon_s > 0.0 else 1.0
        self._s_dt += k * ((gv[0] - gr[0]) * tx + (gv[1] - gr[1]) * ty + (gv[2] - gr[2]) * tz - self._s_dt)
        self._s_tt += k * (tx * tx + ty * ty + tz * tz - self._s_tt)
        if self._s_tt > MIN_TURN_RAD2_S2:
            self.tau_s = min(max(-self._s_dt / self._s_tt, -MAX_LAG_S), MAX_LAG_S)
        return self.tau_s

    def move(self, qv: Quat, w: Vec) -> Quat:
        """VQF's attitude ``qv`` (sensor → earth) turned on by the gyro ``w`` over the lag: at RIANN's instant."""
        t = self.tau_s
        if t == 0.0:
            return qv
        return qmul(qv, from_rotvec(w[0] * t, w[1] * t, w[2] * t))


__all__ = ["LAG_TAUS", "MAX_LAG_S", "MIN_TURN_RAD2_S2", "RelativeLag"]
