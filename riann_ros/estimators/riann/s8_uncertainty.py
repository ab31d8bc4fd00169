"""Stage 8, the uncertainty: a standard deviation per output sample for its inclination and its heading (ROS-free).

Read-only: it takes what the other stages already computed and never changes the attitude. Inclination: roll and
pitch errors as an isotropic 2-D Gaussian with per-axis standard deviation ``σ_i``::

    σ_i² = σ₀² + (k_s·s)² + (k_b·σ_b)² + σ_h²

``s`` the spread of the ensemble copies' gravity directions at the sample's network row (stage 4: where the copies
disagree the network is off), ``σ_b`` the bias front end's σ of its gyro-bias estimate before the sample (stage 3:
a bias error tilts the network's estimate by about the bias times its memory, ``k_b`` seconds), ``σ_h`` the
hand-over's σ after a hole (stage 6). The constants are fitted on the 12 shared BROAD trials by maximum likelihood
(``bench/fit_uncertainty.py``). The rotation rate |ω − b| and the linear acceleration | |a| − g | (low-passed with
:data:`TAU_MOTION`) were measured as candidates too and are kept as features: with the copies' spread in the model
they add nothing (the fit gives them ~0 for the linear acceleration and lowers per-trial coverage with the rate);
docs/riann.md, stage 8.

Heading: without a field the heading is unobservable (:data:`YAW_FREE_SD`). With a field, the field's σ while it
corrects (:data:`~riann_ros.defaults.MAG_HEADING_SD_DEG`), growing with the gyro's drift (the bias σ × time) since
the last field correction while fields are rejected or absent.
"""

from __future__ import annotations

import math

import numpy as np

from riann_ros.defaults import MAG_HEADING_SD_DEG, YAW_FREE_SD_DEG
from riann_ros.estimators.base import Array
from riann_ros.estimators.riann.stage import Cause, GridBlock, Row6, Vec

G = 9.81  # m/s²
DEG = math.pi / 180.0
TAU_MOTION = 0.5  # s; low-pass of the rotation rate and the linear acceleration
# the fitted constants (bench/fit_uncertainty.py on the 12 shared BROAD trials)
SIGMA0 = 0.187 * DEG  # rad
K_SPREAD = 0.865  # rad per rad of spread
K_BIAS = 2.77  # s: rad of tilt per rad/s of bias σ
YAW_FREE_SD = YAW_FREE_SD_DEG * DEG  # rad: the heading without a field
MAG_SD = MAG_HEADING_SD_DEG * DEG  # rad: the heading while a field corrects it
FEATURES = ("spread", "rate", "lin", "handover", "bias_sigma")


class Uncertainty:
    """Stage 8 (see the module docstring). :attr:`sigma`: (n, 2) per sample of the last block, rad."""

    NAME = "uncertainty"

    def __init__(self) -> None:
        self.sigma = np.zeros((0, 2))
        self.features = np.zeros((0, len(FEATURES)))  # of the last block (the fit reads them)
        self.restart(Cause.RESET)

    def restart(self, cause: Cause) -> None:
        self.spread = 0.0  # the newest network row's spread
        self.rate_lp = self.lin_lp = 0.0
        self.started = False
        if cause is Cause.RESET:
            self.since_mag = math.inf  # s since the last field correction (inf: none yet)

    def run(self, g: GridBlock, spread: Array, bias_sigma: list[float], x: list[Row6], bias: list[Vec],
            dt: list[float], tilt_sd: list[float], mag_used: list[bool]) -> Array:
        """Per sample (n, 2): the inclination's σ per axis and the heading's σ (rad)."""
        n = len(x)
        f = np.empty((n, len(FEATURES)))
        yaw = np.empty(n)
        sp = spread.tolist()
        for i in range(n):
            r0, r1 = g.r0[i], g.r1[i]
            if r1 > r0:
                self.spread = sp[r1 - 1]
            b = bias[r0]
            xi = x[i]
            w = math.sqrt((xi[3] - b[0]) ** 2 + (xi[4] - b[1]) ** 2 + (xi[5] - b[2]) ** 2)
            lin = abs(math.sqrt(xi[0] * xi[0] + xi[1] * xi[1] + xi[2] * xi[2]) - G)
            if self.started:
                a = min(dt[i] / TAU_MOTION, 1.0)
                self.rate_lp += a * (w - self.rate_lp)
                self.lin_lp += a * (lin - self.lin_lp)
            else:
                self.rate_lp, self.lin_lp, self.started = w, lin, True
            bs = bias_sigma[r0]
            f[i] = (self.spread, self.rate_lp, self.lin_lp, tilt_sd[i] * DEG, bs)
            yaw[i] = self._yaw(mag_used[i], bs, dt[i])
        self.features = f
        self.sigma = np.column_stack([inclination_sigma(f), yaw])
        return self.sigma

    def _yaw(self, used: bool, bias_sigma: float, dt: float) -> float:
        if used:
            self.since_mag = 0.0
            return MAG_SD
        if math.isinf(self.since_mag):
            return YAW_FREE_SD
        self.since_mag += dt
        return min(math.hypot(MAG_SD, bias_sigma * self.since_mag), YAW_FREE_SD)

    def diagnostics(self) -> dict[str, str]:
        if not len(self.sigma):
            return {}
        return {"inclination sd (deg)": f"{self.sigma[-1, 0] / DEG:.2f}",
                "heading sd (deg)": f"{self.sigma[-1, 1] / DEG:.1f}"}


def inclination_sigma(f: Array, k: tuple[float, float, float] = (SIGMA0, K_SPREAD, K_BIAS)) -> Array:
    """σ_i (rad) of feature rows ``f`` (columns :data:`FEATURES`) with the constants ``k`` (σ₀, k_s, k_b)."""
    s0, ks, kb = k
    return np.sqrt(s0 * s0 + (ks * f[:, 0]) ** 2 + (kb * f[:, 4]) ** 2 + f[:, 3] ** 2)
