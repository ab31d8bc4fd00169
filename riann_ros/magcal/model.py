"""The calibration's linear model (numpy, ROS-free): one window's constraint, the prior, the covariances.

Unknowns ``A = S`` (soft iron) and ``c = A h`` (hard iron through the soft iron), so the window constraint
``A m₀ − c − R(P) (A m₁ − c) = 0`` (:mod:`.windows`) is *linear*: no linearisation, no iteration. ``A`` is
``S_ref + Σ aᵢ Bᵢ``: ``S_ref`` the prior's soft iron, ``Bᵢ`` an orthonormal (Frobenius) basis of the soft-iron
model (``none``: no Bᵢ; ``symmetric``: symmetric matrices; ``full``: all 3×3) *orthogonal to* ``S_ref``. The
constraint is homogeneous in ``(A, c)``: their common scale (the field's strength) is unobservable, and leaving the
direction of ``S_ref`` out of the basis fixes it (``⟨A, S_ref⟩ = |S_ref|²``: for an identity prior, trace S = 3).
A heading does not depend on that scale. Parameters ``θ = (a, c)``, c in µT.

Only directions the windows know at least as well as the prior move the estimate (:func:`posterior`).

One window's residual is ``r = r₀ + J θ`` with a noise of variance (isotropic, µT²)
``2 g² σ_m² + σ_env² + σ_φ² |B|²``: the two readings' noise through ``A`` (``g² = |A|²_F / 3``), the field's
change along the path (a part growing with the window's length), and the gyro's error over the window (bias
residual × length, scale error × angle, latency uncertainty × the rates at its ends) times the field's strength.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from riann_ros.magcal.records import (
    FIELD_CHANGE_RATE_UT_S,
    FIELD_CHANGE_SD_UT,
    GYRO_BIAS_RESIDUAL_SD_RAD_S,
    GYRO_SCALE_SD,
    MAG_NOISE_SD_UT,
    SOFT_IRON_MODELS,
    SYSTEMATIC_SD_UT,
    UT,
    MagCalPrior,
    SoftIronModel,
)
from riann_ros.magcal.windows import WindowSet

Array = NDArray[Any]
PRIOR_FLOOR = 1e-12  # added to the prior covariance's diagonal: keeps a saved, nearly singular one invertible
#: the data moves the estimate only in directions it knows at least this well relative to the prior (ratio of
#: information): in a direction the motion barely observes (a gyro noise's wobble of the turning axis), the
#: windows' pull is noise whose expected shift is σ_prior·√ratio — at 2 % of the prior's information, 0.14 σ_prior
#: (7 µT of a 50 µT prior) for a component the motion does not observe.
OBSERVED_RATIO = 1.0


_SWAP = np.eye(9)[[3 * (k % 3) + k // 3 for k in range(9)]]  # vec(Mᵀ) = _SWAP vec(M), row-major
#: the projectors onto the symmetric and the antisymmetric 3×3 matrices (row-major vec). A rotation by a small angle
#: α about an axis is the antisymmetric [α]×, whose Frobenius norm is √2 α: a prior of σ per axis is σ² · ANTI.
SYM = 0.5 * (np.eye(9) + _SWAP)
ANTI = 0.5 * (np.eye(9) - _SWAP)


def rotation_matrix(q: tuple[float, float, float, float]) -> Array:
    """R(q) of a unit quaternion (w, x, y, z)."""
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def rotation_matrices(q: Array) -> Array:
    """R(q) (W, 3, 3) of unit quaternions (W, 4)."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
                     np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
                     np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)], -2)


def _model_span(model: SoftIronModel) -> Array:
    """An orthonormal basis (9, p) of the soft-iron model's matrices (row-major vec)."""
    if model == "none":
        return np.zeros((9, 0))
    if model == "full":
        return np.eye(9)
    cols = []
    for i in range(3):
        for j in range(i, 3):
            m = np.zeros((3, 3))
            m[i, j] = m[j, i] = 1.0
            cols.append(m.reshape(9) / np.linalg.norm(m))
    return np.array(cols).T


def soft_iron_basis(model: SoftIronModel, s_ref: Array) -> Array:
    """The basis (9, p) of :mod:`this module's docstring <riann_ros.magcal.model>`: the model's matrices
    orthogonal to ``s_ref`` (whose direction, the scale, is unobservable)."""
    if model not in SOFT_IRON_MODELS:
        raise ValueError(f"soft-iron model must be one of {', '.join(SOFT_IRON_MODELS)}, got {model!r}")
    span = _model_span(model)
    if span.shape[1] == 0:
        return span
    u = span.T @ (s_ref.reshape(9) / np.linalg.norm(s_ref))  # the scale direction within the model
    if np.linalg.norm(u) < 1e-9:
        return span
    _, _, vt = np.linalg.svd(u[None, :])
    return span @ vt[1:].T  # the model's directions orthogonal to it


class CalModel:
    """The linear model for one run: its reference soft iron and basis (see the module docstring)."""

    def __init__(self, model: SoftIronModel, s_ref: Array) -> None:
        self.model = model
        self.s_ref = np.asarray(s_ref, dtype=float).reshape(3, 3)
        self.basis = soft_iron_basis(model, self.s_ref)  # (9, p)
        self.p = self.basis.shape[1]
        self.n = self.p + 3
        self.mats = self.basis.T.reshape(self.p, 3, 3)  # the Bᵢ

    def soft_iron(self, theta: Array) -> Array:
        return self.s_ref + np.tensordot(theta[: self.p], self.mats, axes=1)

    def split(self, theta: Array) -> tuple[Array, Array]:
        """``(S, h)`` with h in µT."""
        a = self.soft_iron(theta)
        return a, np.linalg.solve(a, theta[self.p:])

    def rows(self, ws: WindowSet) -> tuple[Array, Array]:
        """``(J (W, 3, n), r₀ (W, 3))`` of the windows' residuals ``r = r₀ + J θ``."""
        p = rotation_matrices(ws.rot)
        m0, m1 = ws.m0_ut, ws.m1_ut
        j = np.empty((len(ws), 3, self.n))
        if self.p:
            b0 = np.einsum("kij,wj->wik", self.mats, m0)  # (W, 3, p): Bₖ m₀
            b1 = np.einsum("kij,wj->wik", self.mats, m1)
            j[:, :, : self.p] = b0 - p @ b1
        j[:, :, self.p:] = p - np.eye(3)
        r0 = m0 @ self.s_ref.T - np.einsum("wij,wj->wi", p, m1 @ self.s_ref.T)
        return j, r0

    def window_var(self, ws: WindowSet, a: Array, c: Array) -> Array:
        """µT²; the variance of each component of each window's residual (W,) (module docstring)."""
        g2 = float(np.sum(a * a)) / 3.0
        b2 = np.sum((ws.m1_ut @ a.T - c) ** 2, axis=1)
        phi2 = ((GYRO_BIAS_RESIDUAL_SD_RAD_S * ws.duration_s) ** 2 + (GYRO_SCALE_SD * ws.angle_rad) ** 2
                + ws.delay_sd_s ** 2 * (ws.rate0_rad_s ** 2 + ws.rate1_rad_s ** 2))
        env2 = FIELD_CHANGE_SD_UT ** 2 + (FIELD_CHANGE_RATE_UT_S * ws.duration_s) ** 2
        return 2.0 * g2 * MAG_NOISE_SD_UT ** 2 + env2 + phi2 * b2

    def prior(self, prior: MagCalPrior) -> tuple[Array, Array]:
        """``(Λ₀, θ₀)``: the prior's information and mean in θ."""
        s0 = np.asarray(prior.soft_iron).reshape(3, 3)
        h0 = np.asarray(prior.hard_iron_t) / UT
        if prior.covariance is not None:
            scale = np.r_[np.ones(9), np.full(3, 1.0 / UT)]
            cov = np.asarray(prior.covariance).reshape(12, 12) * np.outer(scale, scale)
        else:
            cov = np.zeros((12, 12))
            cov[:9, :9] = prior.soft_iron_sd ** 2 * SYM + prior.misalignment_sd_rad ** 2 * ANTI
            cov[9:, 9:] = np.eye(3) * (prior.hard_iron_sd_t / UT) ** 2
        g = np.zeros((self.n, 12))  # d θ / d (vec S, h)
        g[: self.p, :9] = self.basis.T
        for i in range(3):
            g[self.p + i, 3 * i: 3 * i + 3] = h0
        g[self.p:, 9:] = s0
        cov_t = g @ cov @ g.T
        cov_t = 0.5 * (cov_t + cov_t.T) + PRIOR_FLOOR * np.eye(self.n)
        theta0 = np.r_[self.basis.T @ (s0 - self.s_ref).reshape(9), s0 @ h0]
        return np.linalg.inv(cov_t), theta0

    def output_covariance(self, theta: Array, cov: Array) -> Array:
        """The covariance (12, 12) of ``(vec S, h)`` (h in µT) for θ's covariance ``cov``."""
        a, h = self.split(theta)
        ainv = np.linalg.inv(a)
        g = np.zeros((12, self.n))
        g[:9, : self.p] = self.basis
        if self.p:
            g[9:, : self.p] = -ainv @ (self.mats @ h).T
        g[9:, self.p:] = ainv
        out = g @ cov @ g.T
        return 0.5 * (out + out.T)

    def with_floor(self, cov: Array) -> Array:
        """``cov`` with the hard iron's (``c``'s) variance raised to at least :data:`SYSTEMATIC_SD_UT`² in every
        direction (a floor, not a sum: a saved covariance loaded as the next run's prior is not floored twice)."""
        out = cov.copy()
        c = out[self.p:, self.p:]
        lam, v = np.linalg.eigh(0.5 * (c + c.T))
        out[self.p:, self.p:] = c + (v * np.maximum(SYSTEMATIC_SD_UT ** 2 - lam, 0.0)) @ v.T
        return out

    def field_jacobian_t(self, m_ut: Array, w: Array) -> Array:
        """``J_uᵀ w`` (n,) for the calibrated field ``u = A m − c`` and a sensor-frame direction ``w``: the
        sensitivity of ``w · u`` to θ."""
        out = np.empty(self.n)
        if self.p:
            out[: self.p] = self.mats @ m_ut @ w
        out[self.p:] = -w
        return out

    def field_covariance(self, m_ut: Array, cov: Array) -> Array:
        """µT²; the covariance (3, 3) of the calibrated field of the raw reading ``m_ut`` from θ's ``cov``."""
        ju = np.empty((3, self.n))
        if self.p:
            ju[:, : self.p] = (self.mats @ m_ut).T
        ju[:, self.p:] = -np.eye(3)
        return ju @ cov @ ju.T


def heading_sd_bound(model: CalModel, theta: Array, cov: Array, q: tuple[float, float, float, float],
                     u_ut: Array, headings: int) -> float:
    """rad; the largest heading error σ the calibration (θ, ``cov``) adds at the tilt of ``q`` (sensor → world),
    over ``headings`` headings around the vertical, for the world field of the calibrated reading ``u_ut``."""
    r = rotation_matrix(q)
    f = r @ u_ut
    fh = math.hypot(f[0], f[1])
    if fh <= 0.0:
        return math.pi
    e = np.array([f[1], -f[0], 0.0]) / fh  # horizontal, across the field: the heading's direction of error
    a = model.soft_iron(theta)
    c = theta[model.p:]
    worst = 0.0
    for k in range(headings):
        psi = 2.0 * math.pi * k / headings
        rz = np.array([[math.cos(psi), -math.sin(psi), 0.0], [math.sin(psi), math.cos(psi), 0.0], [0.0, 0.0, 1.0]])
        rk = rz @ r
        m = np.linalg.solve(a, rk.T @ f + c)  # the raw reading at that heading
        v = model.field_jacobian_t(m, rk.T @ e)
        worst = max(worst, float(v @ cov @ v))
    return math.sqrt(worst) / fh


def posterior(lam0: Array, theta0: Array, lam_d: Array, eta_d: Array, overstated: float = 1.0
              ) -> tuple[Array, Array, int]:
    """``(θ, covariance, observed directions)`` of the prior ``(Λ₀, θ₀)`` and the windows' information
    ``(Λ_d, η_d)``, keeping of the data only the directions it knows at least as well as the prior
    (:data:`OBSERVED_RATIO`): in the prior-whitened frame, the eigen-directions of ``Λ_d`` with eigenvalue ≥ 1
    (≥ ``overstated`` when ``Λ_d`` overstates the information by that factor: overlapping windows)."""
    l0 = np.linalg.cholesky(lam0)  # Λ₀ = L Lᵀ
    li = np.linalg.inv(l0)
    m = li @ lam_d @ li.T
    lam, v = np.linalg.eigh(0.5 * (m + m.T))
    keep = lam >= OBSERVED_RATIO * overstated
    vs = v[:, keep]
    lam_eff = lam0 + l0 @ (vs * lam[keep]) @ vs.T @ l0.T
    eta_eff = lam0 @ theta0 + l0 @ vs @ (vs.T @ (li @ eta_d))
    cov = np.linalg.inv(lam_eff)
    cov = 0.5 * (cov + cov.T)
    return cov @ eta_eff, cov, int(np.count_nonzero(keep))
