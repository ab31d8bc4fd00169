"""The magnetometer's latency behind the gyro, estimated online from the field's rotation against the gyro's
(ROS-free): RIANN's stage 7b (:mod:`riann_ros.estimators.riann.s7b_latency`) and the calibration front end of the
classical filters (:mod:`riann_ros.estimators.magcal_slot`, for the windows' ends) use it.

docs/riann.md, stage 7 (the heading), and docs/magnetometer.md.
"""

from __future__ import annotations

import math

from riann_ros.rotations import IDENTITY, Quat, Vec, cross, qmul, rotate

# online latency fit (LatencyEstimator)
WINDOW = 0.1  # s; the field's rotation is compared with the gyro's over windows this long
MAX_WINDOW = 0.2  # s; a longer window (no field, a gap) is dropped
DELAY_TAU = 30.0  # s of windows; older windows are forgotten with this time constant
DELAY_PRIOR = 1.0  # (rad/s)²; the starting value weighs as much as one window with a 1 rad/s change of rate
MAX_DELAY = 0.1  # s; the largest latency compensated


class LatencyEstimator:
    """Online, reference-free estimate of the magnetometer's latency ``D`` behind the gyro.

    A constant world field seen by a rotating sensor obeys ``m(t₁) = R(ρ)ᵀ m(t₀)``, ``ρ`` the gyro's rotation
    from ``t₀`` to ``t₁``. A field read ``D`` late rotates as the gyro did ``D`` earlier; to first order the
    prediction error over a window is ``e = m₁ − R(ρ)ᵀ m₀ ≈ D g`` with ``g = ω₁ × R(ρ)ᵀ m₀ − R(ρ)ᵀ (ω₀ × m₀)``
    (``ω₀``, ``ω₁`` the rates at the window's ends). ``D`` is the least-squares fit of ``e`` on ``g`` over
    windows of :data:`WINDOW` s with exponential forgetting (:data:`DELAY_TAU`), both normalised by ``|m|²``
    and started from a prior (the ``mag_delay`` parameter, weight :data:`DELAY_PRIOR`). Windows carry
    information only while the rate changes, so at rest the estimate holds. Noise in the field enters ``e``
    and ``g`` in ways that cancel in ``e·g`` (``n · (ω × n) = 0``), so the fit is unbiased by it; a constant
    hard-iron residual adds a term uncorrelated with ``g`` on average. Windows with a disturbed field are not
    used (the model needs a constant world field).
    """

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self.m0: Vec | None = None  # field at the window's start
        self.w0 = self.w = (0.0, 0.0, 0.0)  # rate at the window's start, newest rate (rad/s)
        self.rho: Quat = IDENTITY  # gyro rotation since the window's start
        self.t = 0.0  # s since the window's start
        self.num = self.den = 0.0  # Σ e·g, Σ g·g (normalised, forgotten)
        self.windows = 0

    def delay(self, start: float) -> float:
        """The latency to compensate (s): the fit with ``start`` as its prior, within [0, MAX_DELAY]."""
        d = (DELAY_PRIOR * start + self.num) / (DELAY_PRIOR + self.den)
        return min(max(d, 0.0), MAX_DELAY)

    def add(self, delta: Quat, rv: Vec, dt: float,
            mag: Vec | None) -> None:
        """One sample: its gyro increment (quaternion and rotation vector) and its undisturbed field or None."""
        if dt > 0.0:
            self.w = (rv[0] / dt, rv[1] / dt, rv[2] / dt)
        if self.m0 is not None:
            self.rho = qmul(self.rho, delta)
            self.t += dt
            if self.t < WINDOW:
                return
            if mag is not None and self.t <= MAX_WINDOW:
                self._fit(mag)
        if mag is not None:
            self.m0, self.w0, self.rho, self.t = mag, self.w, IDENTITY, 0.0
        else:
            self.m0 = None

    def _fit(self, m1: Vec) -> None:
        m0 = self.m0
        assert m0 is not None
        rc = (self.rho[0], -self.rho[1], -self.rho[2], -self.rho[3])
        p = rotate(rc, m0)
        w0, w1 = self.w0, self.w
        c0 = rotate(rc, cross(w0, m0))
        c1 = cross(w1, p)
        g = (c1[0] - c0[0], c1[1] - c0[1], c1[2] - c0[2])
        n2 = m0[0] * m0[0] + m0[1] * m0[1] + m0[2] * m0[2]
        if n2 <= 0.0:
            return
        f = math.exp(-self.t / DELAY_TAU)
        self.num = f * self.num + ((m1[0] - p[0]) * g[0] + (m1[1] - p[1]) * g[1] + (m1[2] - p[2]) * g[2]) / n2
        self.den = f * self.den + (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]) / n2
        self.windows += 1
