"""The magnetometer's latency behind the gyro, estimated online from the field's rotation against the gyro's
(ROS-free), and the gyro history that rotates a late field back over it: part of the magnetometer's front end
(:class:`~riann_ros.magcal.frontend.MagFrontEnd`), which every estimator shares: the calibration's windows end at
the estimated latency, and RIANN's heading compensates it.

docs/riann.md, stage 7 (the heading), and docs/magnetometer.md.
"""

from __future__ import annotations

import math

import numpy as np

from riann_ros.magcal.model import rotation_matrix
from riann_ros.magcal.records import HARD_IRON_PRIOR_SD_T
from riann_ros.rotations import IDENTITY, Quat, Vec, cross, from_rotvec, qmul, rotate, to_rotvec

# online latency fit (LatencyEstimator)
WINDOW = 0.1  # s; the field's rotation is compared with the gyro's over windows this long
MAX_WINDOW = 0.2  # s; a longer window (no field, a gap) is dropped
DELAY_TAU = 30.0  # s of windows; older windows are forgotten with this time constant
DELAY_PRIOR = 1.0  # (rad/s)²; the starting value weighs as much as one window with a 1 rad/s change of rate
MAX_DELAY = 0.1  # s; the largest latency compensated
#: s; how far the starting value may be from the latency: nothing is known of it but its range [0, MAX_DELAY] (the
#: standard deviation of a uniform distribution over it). DELAY_PRIOR is the weight of this much doubt.
DELAY_PRIOR_SD = MAX_DELAY / math.sqrt(12.0)
_NOISE2 = DELAY_PRIOR * DELAY_PRIOR_SD * DELAY_PRIOR_SD  # a window's normalised noise variance (class docstring)
#: degrees of freedom the prior's noise variance weighs as in the windows' own (their residuals, forgotten alike)
NOISE_PRIOR_DOF = 30.0
_B_PRIOR = _NOISE2 / (HARD_IRON_PRIOR_SD_T * HARD_IRON_PRIOR_SD_T)  # the weight of b's prior (b in T)


class LatencyEstimator:
    """Online, reference-free estimate of the magnetometer's latency ``D`` behind the gyro.

    A constant world field seen by a rotating sensor obeys ``m(t₁) = R(ρ)ᵀ m(t₀)``, ``ρ`` the gyro's rotation
    from ``t₀`` to ``t₁``. A field read ``D`` late rotates as the gyro did ``D`` earlier; to first order the
    prediction error over a window is ``e = m₁ − R(ρ)ᵀ m₀ ≈ D g + (I − R(ρ)ᵀ) b`` with ``g = ω₁ × R(ρ)ᵀ u₀ −
    R(ρ)ᵀ (ω₀ × u₀)`` (``ω₀``, ``ω₁`` the rates at the window's ends, ``u₀ = m₀ − b`` with the last fit's ``b``) and
    ``b`` what is left of a hard iron in the field it is given (a magnetometer not calibrated yet: ``b`` is tens of
    µT, and over the short windows its term is correlated with ``g``, so a fit of ``D`` alone would take it for
    latency). ``D`` and ``b`` are the joint least-squares fit over windows of :data:`WINDOW` s with exponential
    forgetting (:data:`DELAY_TAU`), each window normalised by its ``|m₀|``, started from a prior (the ``mag_delay``
    parameter, weight :data:`DELAY_PRIOR`; ``b``: zero, the calibration's prior σ per axis,
    :data:`~riann_ros.magcal.records.HARD_IRON_PRIOR_SD_T`). Windows carry information only while the rate
    changes, so at rest the estimate holds. Noise in the field enters ``e`` and ``g`` in ways that cancel in ``e·g``
    (``n · (ω × n) = 0``), so the fit is unbiased by it. Windows with a disturbed field are not used (the model
    needs a constant world field). :meth:`sd` is the fit's standard deviation, with the windows' normalised noise
    variance measured from their residuals (started from the one :data:`DELAY_PRIOR` weighs :data:`DELAY_PRIOR_SD`
    with, worth :data:`NOISE_PRIOR_DOF` degrees of freedom).
    """

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self.m0: Vec | None = None  # field at the window's start
        self.w0 = self.w = (0.0, 0.0, 0.0)  # rate at the window's start, newest rate (rad/s)
        self.rho: Quat = IDENTITY  # gyro rotation since the window's start
        self.t = 0.0  # s since the window's start
        self.normal = np.zeros((4, 4))  # Σ AᵀA of the windows (forgotten), A = [g, I − R(ρ)ᵀ] / |m₀|
        self.rhs = np.zeros(4)  # Σ Aᵀe
        self.see = self.count = 0.0  # Σ eᵀe, Σ 1 (the residuals' scale)
        self.windows = 0
        self._fit_for: tuple[float, int] | None = None  # (prior, windows) of the cached solution
        self._d = self._var = 0.0
        self._b = (0.0, 0.0, 0.0)  # T; the hard iron of the last solution

    def delay(self, start: float) -> float:
        """The latency to compensate (s): the fit with ``start`` as its prior, within [0, MAX_DELAY]."""
        if self._fit_for != (start, self.windows):
            self._solve(start)
        return min(max(self._d, 0.0), MAX_DELAY)

    def sd(self, floor: float) -> float:
        """s; the standard deviation of :meth:`delay` (class docstring): :data:`DELAY_PRIOR_SD` while no window has
        informed it, never below ``floor`` (what the fit cannot resolve: a sample's rounding, the sensor's filter)."""
        self._fresh()
        return math.hypot(floor, math.sqrt(self._var))

    def _fresh(self) -> None:
        """The solution up to date with the windows (with the prior :meth:`delay` was last asked with)."""
        if self._fit_for is None or self._fit_for[1] != self.windows:
            self._solve(0.0 if self._fit_for is None else self._fit_for[0])

    def _solve(self, start: float) -> None:
        prior = np.diag([DELAY_PRIOR, _B_PRIOR, _B_PRIOR, _B_PRIOR])
        cov = np.linalg.inv(self.normal + prior)
        x = cov @ (self.rhs + prior[:, 0] * start)
        rss = max(self.see - 2.0 * float(x @ self.rhs) + float(x @ self.normal @ x), 0.0)
        noise2 = (_NOISE2 * NOISE_PRIOR_DOF + rss) / (NOISE_PRIOR_DOF + max(3.0 * self.count - 4.0, 0.0))
        self._d, self._var = float(x[0]), noise2 * float(cov[0, 0])
        self._b = (float(x[1]), float(x[2]), float(x[3]))
        self._fit_for = (start, self.windows)

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
        self._fresh()
        b = self._b
        u0 = (m0[0] - b[0], m0[1] - b[1], m0[2] - b[2])  # the field the latency delays: without the hard iron
        w0, w1 = self.w0, self.w
        c0 = rotate(rc, cross(w0, u0))
        c1 = cross(w1, rotate(rc, u0))
        n = math.sqrt(u0[0] * u0[0] + u0[1] * u0[1] + u0[2] * u0[2])
        if n <= 0.0:
            return
        a = np.empty((3, 4))
        a[:, 0] = [(c1[i] - c0[i]) / n for i in range(3)]
        a[:, 1:] = (np.eye(3) - rotation_matrix(rc)) / n
        e = np.array([(m1[i] - p[i]) / n for i in range(3)])
        f = math.exp(-self.t / DELAY_TAU)
        self.normal = f * self.normal + a.T @ a
        self.rhs = f * self.rhs + a.T @ e
        self.see = f * self.see + float(e @ e)
        self.count = f * self.count + 1.0
        self.windows += 1


class DelayHistory:
    """The gyro's rotation over the magnetometer's latency, to rotate a late field back to the gyro's time: the gyro
    increments of the last samples, as many as the latency spans (the oldest one in part)."""

    def __init__(self) -> None:
        self.hist: list[tuple[float, float, float, float]] = []  # (dt, rotation vector of the increment)

    def reset(self) -> None:
        self.hist = []

    def rotation(self, delta: Quat, dt: float, delay_s: float) -> Quat:
        """Sensor-frame rotation over the last ``delay_s`` s from the gyro increments, this sample's (``delta`` over
        ``dt``) the newest."""
        rx, ry, rz = to_rotvec(delta)
        self.hist.append((dt, rx, ry, rz))
        r: Quat = IDENTITY
        rem = delay_s
        keep = 0
        for h_dt, hx, hy, hz in reversed(self.hist):
            if rem <= 0.0:
                break
            keep += 1
            f = min(h_dt, rem) / h_dt if h_dt > 0.0 else 0.0
            rem -= h_dt
            r = qmul(from_rotvec(hx * f, hy * f, hz * f), r)
        del self.hist[: len(self.hist) - max(keep, 1)]
        return r
