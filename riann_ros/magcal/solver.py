"""One information-form estimate with its innovation gate (numpy, ROS-free): the online calibration keeps one (and
a candidate while windows are being rejected, :mod:`.online`)."""

from __future__ import annotations

import numpy as np

from riann_ros.magcal.model import Array, CalModel, posterior
from riann_ros.magcal.records import GATE_CHI2, UNIT_WEIGHT_PRIOR_WINDOWS


class InfoEstimate:
    """The prior ``(Λ₀, θ₀)``, the windows' information ``(Λ_d, η_d)`` and the posterior ``θ``, ``cov``
    (:func:`~.model.posterior`); the running variance of unit weight of the windows added."""

    def __init__(self, model: CalModel, lam0: Array, theta0: Array) -> None:
        self.model = model
        self.lam0, self.theta0 = lam0, theta0
        self.lam = np.zeros_like(lam0)
        self.eta = np.zeros(model.n)
        self.theta = theta0
        self.cov = np.linalg.inv(lam0)
        self.chi2 = 0.0  # Σ of the added windows' innovation distances² (times the scale they were tested with)
        self.added = 0
        self.observed = 0  # directions the windows have observed

    @property
    def unit_weight(self) -> float:
        """The added windows' mean innovation distance² per degree of freedom, with
        :data:`~.records.UNIT_WEIGHT_PRIOR_WINDOWS` windows' worth of 1 (≈ 1 when the noise model fits)."""
        n0 = UNIT_WEIGHT_PRIOR_WINDOWS
        return (n0 + self.chi2 / 3.0) / (n0 + self.added)

    def window(self, j: Array, r0: Array, var: float) -> tuple[float, float]:
        """``(d², k)``: a window's innovation distance² against this estimate (its noise ``var`` plus the estimate's
        uncertainty, both scaled by ``k`` = the variance of unit weight when above 1)."""
        r = r0 + j @ self.theta
        k = max(1.0, self.unit_weight)
        s = k * (var * np.eye(3) + j @ self.cov @ j.T)
        return float(r @ np.linalg.solve(s, r)), k

    def passes(self, d2: float) -> bool:
        return d2 <= GATE_CHI2  # False for NaN too

    def add(self, j: Array, r0: Array, var: float, d2: float, k: float) -> None:
        self.chi2 += d2 * k
        self.added += 1
        self.lam = self.lam + (j.T @ j) / var
        self.eta = self.eta - (j.T @ r0) / var
        self.theta, self.cov, self.observed = posterior(self.lam0, self.theta0, self.lam, self.eta)
