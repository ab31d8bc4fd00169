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

Heading (:func:`heading_sigma`): without a field the heading is unobservable (:data:`YAW_FREE_SD`). While a field
corrects it, ``σ_ψ² = σ_m² + (tan(dip)·σ_i)²`` (the corrected heading's σ, fitted by maximum likelihood on the 12
trials in 9D, and the tilt compensation's share of the inclination error); while fields are rejected or absent after
one, that and the gyro's drift ``σ_b·t`` since the last correction.
"""

from __future__ import annotations

import math

import numpy as np

from riann_ros.defaults import YAW_FREE_SD_DEG
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
MAG_SD = 2.6 * DEG  # rad: the field heading's σ while it corrects (fitted; the tilt's share is added per sample)
FEATURES = ("spread", "rate", "lin", "handover", "bias_sigma")
YAW_FEATURES = ("state", "since_field", "tan_dip")  # state: FREE (no field yet), USED (corrected), HELD (since one)
FREE, USED, HELD = 0.0, 1.0, 2.0
MAX_DIP = 80.0 * DEG  # the tilt's share of the heading error is capped at tan(80°)


class Uncertainty:
    """Stage 8 (see the module docstring). :attr:`sigma`: (n, 2) per sample of the last block, rad."""

    NAME = "uncertainty"

    def __init__(self) -> None:
        self.sigma = np.zeros((0, 2))
        self.features = np.zeros((0, len(FEATURES)))  # of the last block (the fit reads them)
        self.yaw_features = np.zeros((0, len(YAW_FEATURES)))
        self.restart(Cause.RESET)

    def restart(self, cause: Cause) -> None:
        self.spread = 0.0  # the newest network row's spread
        self.rate_lp = self.lin_lp = 0.0
        self.started = False
        if cause is Cause.RESET:
            self.since_mag = math.inf  # s since the last field correction (inf: none yet)

    def run(self, g: GridBlock, spread: Array, bias_sigma: list[float], x: list[Row6], bias: list[Vec],
            dt: list[float], tilt_sd: list[float], mag_used: list[bool], dip: list[float]) -> Array:
        """Per sample (n, 2): the inclination's σ per axis and the heading's σ (rad)."""
        frows: list[tuple[float, ...]] = []
        yrows: list[tuple[float, float, float]] = []
        sig: list[tuple[float, float]] = []
        sp = spread.tolist()
        s0, ks, kb, ms = SIGMA0 * SIGMA0, K_SPREAD, K_BIAS, MAG_SD * MAG_SD
        for i, xi in enumerate(x):  # plain floats: the node's hot path is a block of one
            r0, r1 = g.r0[i], g.r1[i]
            if r1 > r0:
                self.spread = sp[r1 - 1]
            b = bias[r0]
            w = math.sqrt((xi[3] - b[0]) ** 2 + (xi[4] - b[1]) ** 2 + (xi[5] - b[2]) ** 2)
            lin = abs(math.sqrt(xi[0] * xi[0] + xi[1] * xi[1] + xi[2] * xi[2]) - G)
            if self.started:
                a = min(dt[i] / TAU_MOTION, 1.0)
                self.rate_lp += a * (w - self.rate_lp)
                self.lin_lp += a * (lin - self.lin_lp)
            else:
                self.rate_lp, self.lin_lp, self.started = w, lin, True
            bs, h = bias_sigma[r0], tilt_sd[i] * DEG
            frows.append((self.spread, self.rate_lp, self.lin_lp, h, bs))
            si = math.sqrt(s0 + (ks * self.spread) ** 2 + (kb * bs) ** 2 + h * h)  # = inclination_sigma
            y = self._yaw(mag_used[i], dt[i], dip[i])
            yrows.append(y)
            if y[0] == FREE:  # = heading_sigma
                sy = YAW_FREE_SD
            else:
                drift = bs * y[1] if y[0] == HELD else 0.0
                sy = min(math.sqrt(ms + (y[2] * si) ** 2 + drift * drift), YAW_FREE_SD)
            sig.append((si, sy))
        self.features = np.array(frows).reshape(-1, len(FEATURES))
        self.yaw_features = np.array(yrows).reshape(-1, len(YAW_FEATURES))
        self.sigma = np.array(sig).reshape(-1, 2)
        return self.sigma

    def _yaw(self, used: bool, dt: float, dip: float) -> tuple[float, float, float]:
        """The heading's inputs of one sample (:data:`YAW_FEATURES`)."""
        if used:
            self.since_mag = 0.0
            return (USED, 0.0, math.tan(min(abs(dip), MAX_DIP)))
        if math.isinf(self.since_mag):
            return (FREE, 0.0, 0.0)
        self.since_mag += dt
        return (HELD, self.since_mag, math.tan(min(abs(dip), MAX_DIP)))

    def diagnostics(self) -> dict[str, str]:
        if not len(self.sigma):
            return {}
        return {"inclination sd (deg)": f"{self.sigma[-1, 0] / DEG:.2f}",
                "heading sd (deg)": f"{self.sigma[-1, 1] / DEG:.1f}"}


def inclination_sigma(f: Array, k: tuple[float, float, float] = (SIGMA0, K_SPREAD, K_BIAS)) -> Array:
    """σ_i (rad) of feature rows ``f`` (columns :data:`FEATURES`) with the constants ``k`` (σ₀, k_s, k_b)."""
    s0, ks, kb = k
    return np.sqrt(s0 * s0 + (ks * f[:, 0]) ** 2 + (kb * f[:, 4]) ** 2 + f[:, 3] ** 2)


def heading_sigma(yf: Array, sigma_i: Array, bias_sigma: Array, mag_sd: float = MAG_SD) -> Array:
    """σ_ψ (rad) of heading feature rows ``yf`` (columns :data:`YAW_FEATURES`), the inclination's σ and the bias σ:
    the field's σ and the tilt's share of it (``tan(dip)·σ_i``, the tilt compensation's error) while a field corrects
    the heading; that and the gyro's drift ``σ_b·t`` while it is held since the last correction; 180° before any
    field (capped there)."""
    base = mag_sd * mag_sd + (yf[:, 2] * sigma_i) ** 2
    drift = np.where(yf[:, 0] == HELD, bias_sigma * yf[:, 1], 0.0)
    s = np.sqrt(base + drift * drift)
    return np.where(yf[:, 0] == FREE, YAW_FREE_SD, np.minimum(s, YAW_FREE_SD))
