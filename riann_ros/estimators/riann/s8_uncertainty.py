"""Stage 8, the uncertainty: a standard deviation per output sample for its inclination and its heading (ROS-free).

Read-only: it takes what the other stages already computed and never changes the attitude. Inclination: roll and
pitch errors as an isotropic 2-D Gaussian with per-axis standard deviation ``σ_i``::

    σ_i² = σ₀² + (k_s·s)² + (k_b·σ_b)² + (k_r·ω)² + σ_h²

``s`` the spread of the ensemble copies' gravity directions at the sample's network row (stage 4: where the copies
disagree the network is off), ``σ_b`` the bias front end's σ of its gyro-bias estimate before the sample (stage 3:
a bias error tilts the network's estimate by about the bias times its memory, ``k_b`` seconds), ``ω`` the rotation
rate |ω − b| low-passed with :data:`TAU_MOTION` (the network's error grows with the motion it has to follow, as the
paper's fast trials show), ``σ₀`` a floor (the reference's own error and the network's at rest), ``σ_h`` the
hand-over's σ after a hole (stage 6). The constants are fitted on the 12 shared BROAD trials by maximum likelihood
(``bench/fit_uncertainty.py``). The linear acceleration | |a| − g | (low-passed alike) was measured as a candidate
too and is kept as a feature: the fit gives it no weight; docs/riann.md, stage 8.

Heading (:func:`heading_sigma`): without a field the heading is unobservable (:data:`YAW_FREE_SD`), and so it is
again after a gap (no bridge) until a field corrects it. From then on ``σ_ψ² = σ_m² + (tan(dip)·σ_i)² + x²``:
``σ_m`` the field heading's own error (mostly a per-place offset, so it does not average out; fitted by maximum
likelihood on the 12 trials in 9D), the tilt compensation's share of the inclination error, and ``x`` the error the
heading carries beyond the field's, which follows the heading stage step by step:

- the first correction after a reset or a gap, with gain ``k``, leaves ``(1 − k)`` of an unknown heading (180°):
  nothing when a field sets it (the start, a re-acquisition), most of it when the field only comes back after the
  re-acquisition's ``tau_mag`` and the heading creeps toward it;
- while no field corrects it (rejected or absent), the gyro's drift ``σ_b·t`` since the last correction adds to it;
- a bridged hole adds :data:`K_BRIDGE` × the bridge's σ (stage 6) in quadrature: the heading the gyro carried over
  the hole (the bridge's σ is a bound made for the inclination's hand-over; the share is fitted on the trials run
  with holes);
- every correction with gain ``k`` (stage 7a: ``dt/τ_mag``, the running mean while it starts or re-acquires) leaves
  ``(1 − k)`` of it: ``x ← (1 − k)(x + σ_b·t)``.

So after a long rejection, a gap or a badly bridged hole the σ stays wide until the field has pulled the heading in,
at the heading stage's own pace.
"""

from __future__ import annotations

import math

import numpy as np

from riann_ros.defaults import YAW_FREE_SD_DEG
from riann_ros.estimators.base import HEADING_CORRECTED, HEADING_HELD, HEADING_UNKNOWN, Array
from riann_ros.estimators.riann.stage import Cause, GridBlock, Row6, Vec

G = 9.81  # m/s²
DEG = math.pi / 180.0
TAU_MOTION = 0.5  # s; low-pass of the rotation rate and the linear acceleration
# the fitted constants (bench/fit_uncertainty.py on the 12 shared BROAD trials)
SIGMA0 = 0.153 * DEG  # rad: a floor (the reference's own error and the network's at rest)
K_SPREAD = 0.569  # rad per rad of spread
K_BIAS = 2.82  # s: rad of tilt per rad/s of bias σ
K_RATE = 0.00152  # s: rad of tilt per rad/s of (low-passed) rotation rate
YAW_FREE_SD = YAW_FREE_SD_DEG * DEG  # rad: the heading without a field
MAG_SD = 2.5 * DEG  # rad: the field heading's σ (fitted; the tilt's share and the carried error are added per sample)
K_BRIDGE = 0.46  # the bridge's σ (a bound, stage 6) as the heading's σ (fitted on the trials with holes)
FEATURES = ("spread", "rate", "lin", "handover", "bias_sigma")
# state: FREE (no field yet, or since a gap), USED (corrected), HELD (since one); bridge, carried: x's parts (rad)
YAW_FEATURES = ("state", "bridge", "carried", "tan_dip")
FREE, USED, HELD = HEADING_UNKNOWN, HEADING_CORRECTED, HEADING_HELD  # the codes heading_state() reports
MAX_DIP = 80.0 * DEG  # the tilt's share of the heading error is capped at tan(80°)


class Uncertainty:
    """Stage 8 (see the module docstring). :attr:`sigma`: (n, 2) per sample of the last block, rad."""

    NAME = "uncertainty"

    def __init__(self) -> None:
        self.sigma = np.zeros((0, 2))
        self.features = np.zeros((0, len(FEATURES)))  # of the last block (the fit reads them)
        self.yaw_features = np.zeros((0, len(YAW_FEATURES)))
        self.x_bridge = self.x_carried = self.since = 0.0
        self.restart(Cause.RESET)

    def restart(self, cause: Cause) -> None:
        self.spread = 0.0  # the newest network row's spread
        self.rate_lp = self.lin_lp = 0.0
        self.started = False
        # a gap has no bridge: the heading is unknown until a field sets it again
        self.known = False  # a field has set the heading (since the reset or the last gap)

    def run(self, g: GridBlock, spread: Array, bias_sigma: list[float], x: list[Row6], bias: list[Vec],
            dt: list[float], tilt_sd: list[float], gain: list[float], dip: list[float],
            bridges: dict[int, float]) -> Array:
        """Per sample (n, 2): the inclination's σ per axis and the heading's σ (rad). ``gain``: per sample the
        heading stage's gain toward the field (0: not corrected); ``bridges``: samples that end a hole → the σ of
        the bridge over it (deg)."""
        frows: list[tuple[float, ...]] = []
        yrows: list[tuple[float, float, float, float]] = []
        sig: list[tuple[float, float]] = []
        sp = spread.tolist()
        s0, ks, kb, kr, ms, kh = SIGMA0 * SIGMA0, K_SPREAD, K_BIAS, K_RATE, MAG_SD * MAG_SD, K_BRIDGE
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
            si = math.sqrt(s0 + (ks * self.spread) ** 2 + (kb * bs) ** 2 + (kr * self.rate_lp) ** 2 + h * h)
            y = self._yaw(gain[i], dt[i], dip[i], bs, bridges.get(i))
            yrows.append(y)
            if y[0] == FREE:  # = heading_sigma
                sy = YAW_FREE_SD
            else:
                sy = min(math.sqrt(ms + (y[3] * si) ** 2 + (kh * y[1]) ** 2 + y[2] * y[2]), YAW_FREE_SD)
            sig.append((si, sy))
        self.features = np.array(frows).reshape(-1, len(FEATURES))
        self.yaw_features = np.array(yrows).reshape(-1, len(YAW_FEATURES))
        self.sigma = np.array(sig).reshape(-1, 2)
        return self.sigma

    def _yaw(self, k: float, dt: float, dip: float, bias_sd: float, bridge: float | None
             ) -> tuple[float, float, float, float]:
        """The heading's inputs of one sample (:data:`YAW_FEATURES`); ``k`` the heading stage's gain toward the
        field, ``bias_sd`` the bias σ (rad/s), ``bridge`` the σ (deg) of a hole's bridge ending at the sample. The
        bridges' share is kept apart (as a bound, before :data:`K_BRIDGE`) so that the fit can scale it."""
        if self.known:
            self.since += dt
            if bridge is not None:
                self.x_bridge = math.hypot(self.x_bridge, bridge * DEG)
        if k > 0.0:
            if self.known:
                self.x_bridge *= 1.0 - k
                self.x_carried = (1.0 - k) * (self.x_carried + bias_sd * self.since)
            else:  # the first correction since the reset or a gap: before it the heading could be anything
                self.x_bridge, self.x_carried = 0.0, (1.0 - k) * YAW_FREE_SD
            self.since, self.known = 0.0, True
            return (USED, self.x_bridge, self.x_carried, math.tan(min(abs(dip), MAX_DIP)))
        if not self.known:
            return (FREE, 0.0, 0.0, 0.0)
        return (HELD, self.x_bridge, self.x_carried + bias_sd * self.since, math.tan(min(abs(dip), MAX_DIP)))

    def diagnostics(self) -> dict[str, str]:
        if not len(self.sigma):
            return {}
        return {"inclination sd (deg)": f"{self.sigma[-1, 0] / DEG:.2f}",
                "heading sd (deg)": f"{self.sigma[-1, 1] / DEG:.1f}"}


def inclination_sigma(f: Array, k: tuple[float, float, float, float] = (SIGMA0, K_SPREAD, K_BIAS, K_RATE)) -> Array:
    """σ_i (rad) of feature rows ``f`` (columns :data:`FEATURES`) with the constants ``k`` (σ₀, k_s, k_b, k_r); the
    per-sample formula of :meth:`Uncertainty.run`."""
    s0, ks, kb, kr = k
    return np.sqrt(s0 * s0 + (ks * f[:, 0]) ** 2 + (kb * f[:, 4]) ** 2 + (kr * f[:, 1]) ** 2 + f[:, 3] ** 2)


def heading_sigma(yf: Array, sigma_i: Array, mag_sd: float = MAG_SD, k_bridge: float = K_BRIDGE) -> Array:
    """σ_ψ (rad) of heading feature rows ``yf`` (columns :data:`YAW_FEATURES`) and the inclination's σ: the field's
    σ, the tilt's share of it (``tan(dip)·σ_i``, the tilt compensation's error) and the heading's excess error, the
    bridges' share scaled by ``k_bridge`` (the module docstring); 180° before any field and after a gap until one
    (capped there)."""
    s = np.sqrt(mag_sd * mag_sd + (yf[:, 3] * sigma_i) ** 2 + (k_bridge * yf[:, 1]) ** 2 + yf[:, 2] ** 2)
    return np.where(yf[:, 0] == FREE, YAW_FREE_SD, np.minimum(s, YAW_FREE_SD))
