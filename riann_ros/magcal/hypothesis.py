"""The configured calibration as a hypothesis the gyro tests (numpy, ROS-free).

A configured (or saved) calibration ``θ₀`` is either right — to within what a calibrated magnetometer's heading
already carries, the field heading's own σ (:data:`~.records.FIELD_HEADING_SD_RAD`) — or it is not (a robot's
motors, battery and frame add tens of µT nobody measured). The windows' gyro-aided constraint (:mod:`.model`) tells
the two apart: under ``H₀`` ("``θ₀`` is right") each window's residual at ``θ₀`` is the window's noise plus what
the tolerance allows; under ``H₁`` ("``θ`` is unknown, the prior's σ") the windows point to another ``θ``.

While ``H₀`` holds and is the more probable hypothesis (:attr:`PriorTest.p_holds` ≥ ½) the field is used as
configured, with the doubt the windows leave in the heading's σ; while the windows make it the less probable one,
the calibration's own estimate and σ are used; once the test rejects it, they take over for the rest of the robot's
run (the decision is kept over a reset and a hole: the sensor is the same).

The test (:meth:`PriorTest.add`) is the generalised likelihood ratio of ``H₀`` against ``H₁`` on the windows the
estimate holds: ``D² = δᵀ Λ_d (I + C_tol Λ_d)⁻¹ δ`` with ``δ = θ̂ − θ₀``, ``Λ_d`` the windows' information and
``C_tol`` the tolerance's covariance, divided by the variance of unit weight when it exceeds 1 (windows noisier than
the noise model widen the test with the σ); ``H₀`` is rejected when ``D²`` exceeds the χ² quantile
:data:`PRIOR_REJECT_P` for the directions the windows observe, ``H₁`` is the more probable hypothesis
(:attr:`PriorTest.p_holds` below ½: a large ``D²`` spread over many observed directions is still ``H₀``'s when
the prior of ``H₁`` would have allowed far larger ones), and both still hold without the :data:`ROBUST_WINDOWS`
windows that contradict ``H₀`` the most on their own (a magnetically disturbed window or two that the loose ``H₁``
prior still admits do not reject a calibration that every other window agrees with; evidence spread thinly over
many windows of slow rotation, none of them decisive alone, does).

Until the windows have decided, the heading must not claim a calibrated sensor's σ: :attr:`PriorTest.p_holds` is
the posterior probability of ``H₀`` (Bayes factor of the two linear-Gaussian models on the same windows, each
hypothesis a priori as likely as the other: nothing says whether a robot's magnetometer was calibrated), and the
heading's σ while ``H₀`` is used includes ``(1 − p) (σ₁² + Δ²)``: ``σ₁`` the heading σ under ``H₁``'s estimate and
``Δ`` the heading difference between the two calibrations (:meth:`~.online.OnlineMagCalibrator.heading_sd_rad`).
Before any window (at rest) ``p`` is ½: the field is used, and said to be unverified; every window that agrees with
``H₀`` multiplies its odds by the Occam factor of the directions it observes (tens per direction).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.stats import chi2

from riann_ros.magcal.model import Array, CalModel, posterior, rotation_matrix
from riann_ros.magcal.records import FIELD_HEADING_SD_RAD, GATE_CHI2
from riann_ros.magcal.solver import InfoEstimate

#: the test's false-rejection probability: a right calibration is rejected once in 1000 runs' tests.
PRIOR_REJECT_P = 0.999
#: the test must reject ``H₀`` without this many of the windows that contradict it the most on their own (their
#: residual at θ₀ against their noise and the tolerance): a lone disturbed window, or two, is not evidence against a
#: calibration; the evidence must be in the others.
ROBUST_WINDOWS = 2
_QUANTILE = tuple(float(chi2.ppf(PRIOR_REJECT_P, k)) for k in range(1, 13))
_TAN_TOL = math.tan(FIELD_HEADING_SD_RAD)


class PriorTest:
    """Whether the prior ``θ₀`` still holds (module docstring); :meth:`add` once per window the estimate takes."""

    def __init__(self, model: CalModel, theta0: Array, saved: Array | None = None) -> None:
        self.model = model
        self.theta0 = theta0
        self.saved = saved  # a saved calibration's covariance (None: a configured one)
        self.holds = True
        self.d2 = 0.0  # the last test's D² (diagnostics)
        self.p_holds = 0.5  # the posterior probability of H₀ (module docstring)
        #: the ROBUST_WINDOWS windows that contradict H₀ the most: (their distance², Λ_i, η_i)
        self.worst: list[tuple[float, Array, Array]] = []

    def tolerance(self, u_ut: Array, horizontal_ut: float) -> Array:
        """``C_tol`` (n, n) in θ: per axis of the hard iron the offset whose heading error, across a horizontal
        field of ``horizontal_ut``, is :data:`~.records.FIELD_HEADING_SD_RAD`; per soft-iron direction the same
        error at the field ``u_ut``'s strength; plus a saved calibration's own covariance (its uncertainty when the
        magnetic situation is the one it was estimated in)."""
        tol_h = _TAN_TOL * horizontal_ut
        tol_s = tol_h / max(float(np.linalg.norm(u_ut)), 1e-9)
        tol = np.diag(np.r_[np.full(self.model.p, tol_s * tol_s), np.full(3, tol_h * tol_h)])
        return tol if self.saved is None else tol + self.saved

    def tolerance_at(self, m_ut: Array, q: tuple[float, float, float, float] | None) -> Array:
        """:meth:`tolerance` for the raw reading ``m_ut`` calibrated with θ₀, its horizontal part at the attitude
        ``q`` (sensor → world; None: a mid-latitude dip of 60°)."""
        u = self.model.soft_iron(self.theta0) @ m_ut - self.theta0[self.model.p:]
        horizontal = (float(np.hypot(*(rotation_matrix(q) @ u)[:2])) if q is not None
                      else 0.5 * float(np.linalg.norm(u)))
        return self.tolerance(u, horizontal)

    def window_d2(self, j: Array, r0: Array, var: float, tol: Array) -> float:
        """One window's distance² from ``H₀`` on its own: its residual at θ₀ against its noise and the tolerance."""
        r = r0 + j @ self.theta0
        s = var * np.eye(3) + j @ tol @ j.T
        return float(r @ np.linalg.solve(s, r))

    def window_fails(self, j: Array, r0: Array, var: float, tol: Array) -> bool:
        """Whether one window fails ``H₀`` on its own (at the gate's 99.9 %, :data:`~.records.GATE_CHI2`)."""
        return self.window_d2(j, r0, var, tol) > GATE_CHI2

    def add(self, est: InfoEstimate, j: Array, r0: Array, var: float, tol: Array) -> bool:
        """The test after the estimate ``est`` took the window ``(j, r0, var)``; returns whether ``H₀`` still holds
        (once rejected, never again)."""
        if not self.holds:
            return False
        self._keep_worst(self.window_d2(j, r0, var, tol), (j.T @ j) / var, -(j.T @ r0) / var)
        k = max(1.0, est.unit_weight)
        self.p_holds = self._posterior(est.lam0, est.lam / k, (est.eta - est.lam @ self.theta0) / k, tol)
        self.d2 = self._distance(est.theta, est.lam, k, tol)
        if self._rejects(self.d2, self.p_holds, est.observed):  # and without the windows that contradict it most:
            lam = est.lam - sum(w[1] for w in self.worst)
            eta = est.eta - sum(w[2] for w in self.worst)
            theta, _, observed = posterior(est.lam0, self.theta0, lam, eta)
            p = self._posterior(est.lam0, lam / k, (eta - lam @ self.theta0) / k, tol)
            self.holds = not self._rejects(self._distance(theta, lam, k, tol), p, observed)
        return self.holds

    def _keep_worst(self, d2: float, lam: Array, eta: Array) -> None:
        self.worst.append((d2, lam, eta))
        self.worst.sort(key=lambda w: -w[0])
        del self.worst[ROBUST_WINDOWS:]

    @staticmethod
    def _rejects(d2: float, p_holds: float, observed: int) -> bool:
        dof = min(max(observed, 1), len(_QUANTILE))
        return d2 > _QUANTILE[dof - 1] and p_holds < 0.5

    def _distance(self, theta: Array, lam: Array, k: float, tol: Array) -> float:
        """``D²`` of the estimate ``theta`` from θ₀ with the windows' information ``lam`` (module docstring)."""
        delta = theta - self.theta0
        m = lam @ np.linalg.inv(np.eye(self.model.n) + tol @ lam)
        return float(delta @ (0.5 * (m + m.T)) @ delta) / k

    def _posterior(self, lam0: Array, lam: Array, g: Array, tol: Array) -> float:
        """P(H₀ | windows): the Bayes factor of ``H₀`` (θ ~ N(θ₀, C_tol)) against ``H₁`` (θ ~ N(θ₀, Λ₀⁻¹)) on the
        windows' information ``Λ`` and gradient ``g = η − Λ θ₀``, both scaled by the variance of unit weight;
        ``log B₀₁ = ½ gᵀ[(C_tol⁻¹ + Λ)⁻¹ − (Λ₀ + Λ)⁻¹] g + ½ log det(I + Λ₀⁻¹Λ) − ½ log det(I + C_tol Λ)``."""
        eye = np.eye(self.model.n)
        a0 = tol @ np.linalg.inv(eye + lam @ tol)
        c1 = np.linalg.inv(lam0)
        a1 = np.linalg.inv(lam0 + lam)
        log_b = 0.5 * float(g @ (a0 - a1) @ g)
        log_b += 0.5 * (np.linalg.slogdet(eye + c1 @ lam)[1] - np.linalg.slogdet(eye + tol @ lam)[1])
        return 1.0 / (1.0 + math.exp(min(-log_b, 700.0)))
