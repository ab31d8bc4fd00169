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
(``bench/fit_uncertainty.py``); docs/riann.md, stage 8, has the inputs measured and left out.

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
  ``(1 − k)`` of it: ``x ← (1 − k)(x + σ_b·t)``;
- the online magnetometer calibration's share: a field whose heading the calibration knows to ``σ_c`` (stage 7a;
  0 while the configured calibration holds) moves a part ``x_c`` of the carried error the way it moves the
  heading, ``x_c ← (1 − k) x_c + k σ_c`` (the calibration's error is common to consecutive fields, so it does not
  average out: the heading's share of it is the weighted mean of theirs); while the configured calibration is used,
  the doubt the gyro-aided test leaves about it, ``x_d`` (stage 7a: it concerns every field the heading took
  alike, so the newest value counts, not a mean); ``x`` is ``√(x² + x_c² + x_d²)``.

So after a long rejection, a gap or a badly bridged hole the σ stays wide until the field has pulled the heading in,
at the heading stage's own pace.

Each formula is written once (:func:`inclination_var`, :func:`heading_var`), for plain floats and numpy arrays
alike: :meth:`Uncertainty.run` takes it per sample (the node's call is a block of one), the fit
(:func:`inclination_sigma`, :func:`heading_sigma`) on whole arrays of the features the stage outputs.
"""

from __future__ import annotations

import math
from typing import TypeVar

import numpy as np

from riann_ros.constants import DEG
from riann_ros.defaults import MAG_HEADING_SD_DEG, YAW_FREE_SD_DEG
from riann_ros.estimators.base import HEADING_CORRECTED, HEADING_HELD, HEADING_UNKNOWN, Array
from riann_ros.estimators.riann.stage import Cause, Uncertainties, UncertaintyIn

TAU_MOTION = 0.5  # s; low-pass of the rotation rate
# the fitted constants (bench/fit_uncertainty.py on the 12 shared BROAD trials)
SIGMA0 = 0.153 * DEG  # rad: a floor (the reference's own error and the network's at rest)
K_SPREAD = 0.569  # rad per rad of spread
K_BIAS = 2.82  # s: rad of tilt per rad/s of bias σ
K_RATE = 0.00152  # s: rad of tilt per rad/s of (low-passed) rotation rate
YAW_FREE_SD = YAW_FREE_SD_DEG * DEG  # rad: the heading without a field
MAG_SD = MAG_HEADING_SD_DEG * DEG  # rad: the field heading's σ (the tilt's share and the carried error are added)
K_BRIDGE = 0.46  # the bridge's σ (a bound, stage 6) as the heading's σ (fitted on the trials with holes)
# the inclination's inputs per sample: spread (rad), rate (rad/s), hand-over σ (rad), bias σ (rad/s)
FEATURES = ("spread", "rate", "handover", "bias_sigma")
# state: FREE (no field yet, or since a gap), USED (corrected), HELD (since one); bridge, carried: x's parts (rad)
YAW_FEATURES = ("state", "bridge", "carried", "tan_dip")
FREE, USED, HELD = HEADING_UNKNOWN, HEADING_CORRECTED, HEADING_HELD  # the codes heading_state() reports
MAX_DIP = 80.0 * DEG  # the tilt's share of the heading error is capped at tan(80°)

F = TypeVar("F", float, Array)  # a formula's inputs: one sample's floats, or arrays of samples


def inclination_var(spread: F, rate: F, handover: F, bias_sigma: F,
                    k: tuple[float, float, float, float] = (SIGMA0, K_SPREAD, K_BIAS, K_RATE)) -> F:
    """σ_i² (rad²) from the inputs (:data:`FEATURES`) with the constants ``k`` (σ₀, k_s, k_b, k_r)."""
    s0, ks, kb, kr = k
    return s0 * s0 + (ks * spread) ** 2 + (kb * bias_sigma) ** 2 + (kr * rate) ** 2 + handover * handover


def heading_var(sigma_i: F, bridge: F, carried: F, tan_dip: F, mag_sd: float = MAG_SD,
                k_bridge: float = K_BRIDGE) -> F:
    """σ_ψ² (rad²) of a heading the field has corrected (before the cap at :data:`YAW_FREE_SD`): the field's σ, the
    tilt's share of it (``tan(dip)·σ_i``, the tilt compensation's error) and the heading's excess error, the
    bridges' share scaled by ``k_bridge`` (the module docstring)."""
    return mag_sd * mag_sd + (tan_dip * sigma_i) ** 2 + (k_bridge * bridge) ** 2 + carried * carried


class Uncertainty:
    """Stage 8 (see the module docstring)."""

    NAME = "uncertainty"

    def __init__(self) -> None:
        self.restart(Cause.RESET)

    def restart(self, cause: Cause) -> None:
        """GAP: the rate low-pass and the spread start again, the heading is unknown until a field sets it (a gap
        has no bridge); RESET: all of it anew."""
        self.spread = 0.0  # the newest network row's spread (rad)
        self.rate_lp = 0.0  # rad/s
        self.started = False
        self.known = False  # a field has set the heading (since the reset or the last gap)
        if cause is Cause.RESET:
            self.x_bridge = self.x_carried = self.since = self.x_cal = self.x_doubt = 0.0
            self.last: tuple[float, float] | None = None  # the newest sample's σ (rad), for diagnostics

    def run(self, block: UncertaintyIn) -> Uncertainties:
        """Per sample (n, 2): the inclination's σ per axis and the heading's σ (rad), and the model's inputs."""
        s, g, bias, hand, heading = block.samples, block.grid, block.bias, block.handover, block.heading
        frows: list[tuple[float, float, float, float]] = []
        yrows: list[tuple[float, float, float, float]] = []
        sig: list[tuple[float, float]] = []
        sp = block.net.spread_rad.tolist()
        for i, xi in enumerate(s.x):  # plain floats: the node's hot path is a block of one
            r0, r1 = g.r0[i], g.r1[i]
            if r1 > r0:
                self.spread = sp[r1 - 1]
            b = bias.bias_rad_s[r0]
            w = math.sqrt((xi[3] - b[0]) ** 2 + (xi[4] - b[1]) ** 2 + (xi[5] - b[2]) ** 2)
            if self.started:
                self.rate_lp += min(s.step_s[i] / TAU_MOTION, 1.0) * (w - self.rate_lp)
            else:
                self.rate_lp, self.started = w, True
            bs = bias.sigma_rad_s[r0]
            h = (hand.blend_sd_deg[i] + hand.fresh_sd_deg[i]) * DEG  # never both non-zero
            frows.append((self.spread, self.rate_lp, h, bs))
            si = math.sqrt(inclination_var(self.spread, self.rate_lp, h, bs))
            if heading.gain[i] > 0.0:
                self.x_doubt = heading.doubt_sd_rad[i]
            y = self._yaw(heading.gain[i], s.step_s[i], heading.dip_rad[i], bs, hand.bridge_sd_deg.get(i),
                          heading.cal_sd_rad[i])
            yrows.append(y)
            sy = YAW_FREE_SD if y[0] == FREE else min(math.sqrt(heading_var(si, y[1], y[2], y[3])), YAW_FREE_SD)
            sig.append((si, sy))
        if sig:
            self.last = sig[-1]
        return Uncertainties(np.array(sig).reshape(-1, 2), np.array(frows).reshape(-1, len(FEATURES)),
                             np.array(yrows).reshape(-1, len(YAW_FEATURES)))

    def _yaw(self, k: float, dt: float, dip: float, bias_sd: float, bridge: float | None, cal_sd: float = 0.0
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
                self.x_cal += k * (cal_sd - self.x_cal)
            else:  # the first correction since the reset or a gap: before it the heading could be anything
                self.x_bridge, self.x_carried, self.x_cal = 0.0, (1.0 - k) * YAW_FREE_SD, k * cal_sd
            self.since, self.known = 0.0, True
            return (USED, self.x_bridge, self._carried(self.x_carried), math.tan(min(abs(dip), MAX_DIP)))
        if not self.known:
            return (FREE, 0.0, 0.0, 0.0)
        return (HELD, self.x_bridge, self._carried(self.x_carried + bias_sd * self.since),
                math.tan(min(abs(dip), MAX_DIP)))

    def _carried(self, x: float) -> float:
        """The carried error with the calibration's share (the module docstring)."""
        return math.hypot(x, self.x_cal, self.x_doubt) if self.x_cal or self.x_doubt else x

    def diagnostics(self) -> dict[str, str]:
        if self.last is None:
            return {}
        return {"inclination sd (deg)": f"{self.last[0] / DEG:.2f}", "heading sd (deg)": f"{self.last[1] / DEG:.1f}"}


def inclination_sigma(f: Array, k: tuple[float, float, float, float] = (SIGMA0, K_SPREAD, K_BIAS, K_RATE)) -> Array:
    """σ_i (rad) of feature rows ``f`` (columns :data:`FEATURES`) with the constants ``k`` (σ₀, k_s, k_b, k_r)."""
    return np.sqrt(inclination_var(f[:, 0], f[:, 1], f[:, 2], f[:, 3], k))


def heading_sigma(yf: Array, sigma_i: Array, mag_sd: float = MAG_SD, k_bridge: float = K_BRIDGE) -> Array:
    """σ_ψ (rad) of heading feature rows ``yf`` (columns :data:`YAW_FEATURES`) and the inclination's σ
    (:func:`heading_var`); 180° before any field and after a gap until one (capped there)."""
    s = np.sqrt(heading_var(sigma_i, yf[:, 1], yf[:, 2], yf[:, 3], mag_sd, k_bridge))
    return np.where(yf[:, 0] == FREE, YAW_FREE_SD, np.minimum(s, YAW_FREE_SD))
