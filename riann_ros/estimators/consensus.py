"""The consensus of RIANN and VQF: one inclination from both, weighed by their uncertainties (ROS-free).

RIANN's network and VQF's accelerometer low-pass err in partly independent ways (on BROAD their inclination errors
correlate by +0.10, ``bench/consensus_study.py``), so a weighted mean of the two beats either where both work. The
estimator runs RIANN (:class:`~.riann.estimator.RiannEstimator`, all its stages and parameters) and VQF on the rows
RIANN's stages 1–3 made (:class:`~.consensus_rows.VqfRows`: de-jittered, on a constant step, the gyro bias removed,
holes bridged), and per sample combines their gravity directions:

* **Errors.** Per horizontal axis RIANN's σ is stage 8's ``σ_R``, VQF's ``σ_V`` its state's
  (:mod:`.vqf_sigma`). Their covariance ``c`` is what the two share: the floor ``σ₀²`` (the same accelerometer),
  the two lags of the one bias estimate both use (``K_BIAS σ_b · K_LAG σ_b``, the same sign), the timing error of
  the rows both read (the rotation rate times a quarter of the input step: the sample convention, points or interval
  means, is not known; :data:`TIMING_SHARE`), and
  :data:`RHO_OWN` of the rest (fitted on synthetic sensors, ``bench/fit_consensus.py``).
* **One instant.** VQF's attitude is moved to RIANN's instant by the lag the two opinions show while the sensor
  turns (:class:`~.consensus_lag.RelativeLag`, fitted online): a mean of two attitudes of different instants errs by
  the turn between them.
* **Combination.** The error of ``g = w·g_R + (1 − w)·g_V`` has the variance ``w²σ_R² + (1 − w)²σ_V² + 2w(1 − w)c``,
  least at ``w = (σ_V² − c) / (σ_R² + σ_V² − 2c)`` (with ``c = ρσ_Rσ_V``: ``(σ_V² − ρσ_Rσ_V) / (σ_R² + σ_V² −
  2ρσ_Rσ_V)``), where it is ``σ² = (σ_R²σ_V² − c²) / (σ_R² + σ_V² − 2c)``; ``w`` is kept in [0, 1] (beyond, the
  combination would extrapolate on a correlation it only estimates) and ``σ`` is then the chosen one's.
* **Disagreement.** The angle ``d`` between the two gravity directions is a 2-D Gaussian of per-axis variance
  ``σ_d² = σ_R² + σ_V² − 2c`` while both σ hold. Where ``d² > χ²₂(0.99)·σ_d²`` they part by more than their σ
  explain: the unexplained variance ``d²/χ²₂(0.99) − σ_d²`` goes to the one whose own state is unhealthy (RIANN with
  an unsettled bias; VQF after a hole or a restart, with an unsettled bias or under linear acceleration: its
  transient terms outweigh its steady ones), so the output follows the healthy one; where neither or both are, to
  both in proportion, which keeps the weight. σ then also holds the chance that either is right, as likely as its
  weight: the spread of that two-point mixture about the combination, ``w(1 − w)·d²`` (``/2`` per axis).
* **Holes.** While RIANN's stage 6 hands over after a hole (or its fresh network after a gap is young) the output is
  RIANN's: VQF started at the same instant from the same bridge or from the accelerometer alone (its restart, where
  stage 6's fresh-start σ is below the bridge's), and corrects more slowly (``τ_acc`` against the network's 0.5 s),
  so it holds no independent information then; its σ carries the transient on (:mod:`.vqf_sigma`).
* **What the sensor shows.** ``d`` measures exactly the two own errors (the floor and the common lag cancel in it):
  where both are healthy, ``E[d²] = 2σ_d²``. The ratio of ``d²`` to ``2σ_d²``, each low-passed over
  :data:`SCALE_TAUS` × ``τ_acc``, scales both own variances where it exceeds 1 (a sensor noisier than the models
  know): the weight stays, σ widens. Never below 1: a model more cautious than the data stays so.
* **Heading.** RIANN's output heading (the gyro's, and in 9D the calibrated field's: RIANN's stage 7 drives the
  magnetometer's front end, once per sample), turned by the smallest horizontal rotation onto the combined
  gravity direction (:func:`~riann_ros.rotations.tilt_to`); the heading's σ and state are RIANN's.

Per sample in plain floats (the node's call is one sample), so a batch gives the numbers of per-sample calls.
docs/consensus.md has the derivation and the figures.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from riann_ros.constants import DEG
from riann_ros.estimators.base import Array, AttitudeEstimator, ParamSpec
from riann_ros.estimators.consensus_lag import LAG_TAUS, RelativeLag
from riann_ros.estimators.consensus_rows import DEFAULT_TAU_ACC, VqfRows
from riann_ros.estimators.riann.estimator import RiannEstimator
from riann_ros.estimators.riann.s6_handover import S_FLOOR, FreshNetwork, bridge_sigma
from riann_ros.estimators.riann.s8_uncertainty import K_BIAS
from riann_ros.estimators.riann.stage import Cause, UncertaintyIn
from riann_ros.estimators.vqf_sigma import VqfSigma, VqfTerms
from riann_ros.magcal.frontend import LatencySettings, MagFrontEnd
from riann_ros.rotations import Quat, Vec, gravity, tilt_to

#: correlation of the two estimators' own errors: the maximum-likelihood fit on synthetic sensors is below 0
#: (bench/fit_consensus.py), which two estimators on one input cannot be, so the bound; on BROAD their errors, floor
#: included, correlate by +0.10 (bench/consensus_study.py)
RHO_OWN = 0.0
CHI2_2_99 = 9.210  # χ²₂(0.99): the disagreement test
#: the own errors' scale averages the disagreement over this many VQF time constants (errors that correlate over about
#: one tau_acc: ten of them know the mean square to about a third)
SCALE_TAUS = 10.0
#: a sample read a quarter of its step off: the worst timing error either sample convention leaves (points or interval
#: means; RIANN's sample_delay halves the half step between them, docs/riann.md, stage 1)
TIMING_SHARE = 0.25
#: a sample whose rows span more than twice the usual has at least one lost sample before it; the usual span is a
#: running mean over about this many samples
SKIP_FACTOR = 2.0
SPAN_SAMPLES = 20.0
TAU_ACC = ParamSpec("tau_acc", DEFAULT_TAU_ACC, "s; time constant of VQF's accelerometer low-pass (VQF tauAcc) in the "
                    "consensus's second opinion. Default 3.0 = the vqf package default.", min=0.01, max=1000.0,
                    runtime=True)
_RIANN = {p.name for p in RiannEstimator.PARAMS}


class Opinions(NamedTuple):
    """The two opinions of the samples of the last call: RIANN's output attitudes (n, 4), VQF's (n, 4, its heading
    its own) and VQF's σ terms (n, 5: :class:`~.vqf_sigma.VqfTerms`, rad²); what ``bench/fit_consensus.py`` fits."""

    riann: Array
    vqf: Array
    vqf_terms: Array


class ConsensusEstimator(AttitudeEstimator):
    """RIANN and VQF in consensus (module docstring)."""

    name = "consensus"
    PARAMS = (*RiannEstimator.PARAMS, TAU_ACC)
    USES_MAG = True

    def __init__(self, **params: Any) -> None:
        self.riann = RiannEstimator(**{k: v for k, v in params.items() if k in _RIANN})
        tau = float(params.get("tau_acc", DEFAULT_TAU_ACC))
        self.vqf = VqfRows(tau)
        self.vqf_sigma = VqfSigma(tau)
        super().__init__(**params)

    # -- the two estimators' life cycle ---------------------------------------------------------------------------
    def reset(self) -> None:
        self.riann.reset()
        self.vqf.restart(Cause.RESET)
        self.vqf_sigma.reset()
        self.lag = RelativeLag()  # how far VQF's opinion lags RIANN's (kept through a gap: the same sensor)
        self._after_gap = False
        self.scale, self._lp_d2, self._lp_model = 1.0, 0.0, 0.0  # the own errors' scale and its low-passes
        self._span_lp, self._w_prev = 0.0, (0.0, 0.0, 0.0)  # the usual step of a sample (s), the last gyro
        self._kicks: dict[int, float] = {}  # sample of the last call -> the σ (rad) VQF's attitude starts off by
        self._sigma = np.zeros((0, 2))
        self.last = Opinions(np.zeros((0, 4)), np.zeros((0, 4)), np.zeros((0, 5)))
        self.weight = self.disagreement = math.nan  # of the newest sample: RIANN's weight, the angle (rad)

    def on_gap(self) -> None:
        self.riann.on_gap()
        self.vqf.restart(Cause.GAP)
        self._after_gap = True

    def take_front_end(self, front: MagFrontEnd) -> None:
        super().take_front_end(front)
        self.riann.take_front_end(front)

    def front_end_latency(self) -> LatencySettings:
        return self.riann.front_end_latency()

    def _on_params_changed(self) -> None:
        self.riann.set_params(**{p.name: self.params[p.name] for p in RiannEstimator.PARAMS if p.runtime})
        tau = float(self.params["tau_acc"])
        self.vqf.set_tau_acc(tau)
        self.vqf_sigma.tau_acc = tau

    # -- what the node reports ------------------------------------------------------------------------------------
    def heading_observed(self) -> bool:
        return self.riann.heading_observed()

    def heading_state(self) -> Array:
        return self.riann.heading_state()

    def diagnostics(self) -> dict[str, str]:
        out = self.riann.diagnostics()
        if math.isfinite(self.weight):
            out["consensus weight on RIANN"] = f"{self.weight:.2f}"
            out["RIANN-VQF disagreement (deg)"] = f"{self.disagreement / DEG:.2f}"
            out["consensus sigma scale"] = f"{self.scale:.2f}"
            out["VQF's lag behind RIANN (ms, compensated)"] = f"{self.lag.tau_s * 1e3:.2f}"
        return out

    def sigma(self, fields: np.ndarray) -> Array:
        """The combination's inclination σ and RIANN's heading σ of the samples of the last call."""
        if len(self._sigma) != len(fields):
            raise ValueError(f"sigma for {len(fields)} samples asked, the last call had {len(self._sigma)}")
        return self._sigma.copy()

    # -- estimation -------------------------------------------------------------------------------------------------
    def update(self, acc: ArrayLike, gyr: ArrayLike, dt: float, mag: ArrayLike | None = None) -> Array:
        return self._combine(self.riann.update(acc, gyr, dt, mag)[None, :])[0]

    def update_batch(self, acc: ArrayLike, gyr: ArrayLike, dt: ArrayLike, mag: ArrayLike | None = None) -> Array:
        return self._combine(self.riann.update_batch(acc, gyr, dt, mag))

    def _combine(self, q_r: Array) -> Array:
        """RIANN's outputs of its last call with their inclination replaced by the consensus's (module docstring)."""
        u = self.riann.records
        n = len(q_r)
        if u is None or n == 0:
            self._sigma = np.zeros((0, 2))
            return q_r
        q_v = self.vqf.run(u, self._restarts(u))
        s_r = self.riann.last.sigma_rad
        feats = self.riann.last.features.tolist()
        out = np.empty((n, 4))
        sig = s_r.copy()
        terms = []
        moved: list[Quat] = []
        horizon = LAG_TAUS * self.vqf_sigma.tau_acc
        for i, (qr, fi) in enumerate(zip(q_r.tolist(), feats, strict=True)):
            t = self._vqf_terms(u, i, fi[3])
            terms.append(t)
            x, b = u.samples.x[i], u.bias.bias_rad_s[u.grid.r0[i]]
            w = (x[3] - b[0], x[4] - b[1], x[5] - b[2])
            qv = (float(q_v[i][0]), float(q_v[i][1]), float(q_v[i][2]), float(q_v[i][3]))
            self.lag.step(gravity((qr[0], qr[1], qr[2], qr[3])), gravity(qv), w, u.samples.step_s[i], horizon)
            moved.append(self.lag.move(qv, w))  # VQF at RIANN's instant (riann_ros/estimators/consensus_lag.py)
            out[i], sig[i, 0] = self._one(qr, moved[-1], float(s_r[i, 0]), fi, t, u.samples.step_s[i])
        self._sigma = sig
        self.last = Opinions(q_r, np.asarray(moved, dtype=float).reshape(n, 4), np.array(terms).reshape(n, 5))
        return out

    def _restarts(self, u: UncertaintyIn) -> list[int]:
        """The rows where VQF starts afresh from the accelerometer instead of bridging a hole: where the bridge's σ
        exceeds a fresh start's (stage 6's models of both: :func:`~.riann.s6_handover.bridge_sigma` and
        :class:`~.riann.s6_handover.FreshNetwork`, a filter started from the accelerometer in the motion around the
        hole); VQF's σ starts from the smaller at the hole."""
        out = []
        for h in u.grid.holes:
            bridge = u.handover.bridge_sd_deg[h.sample]
            x = u.samples.x[h.sample]
            w_max = max(math.hypot(*h.w_before_rad_s), math.hypot(*h.w_after_rad_s))
            fresh = FreshNetwork(w_max, (x[0], x[1], x[2])).sigma()
            if bridge > fresh:
                out.append(u.grid.r1[h.sample])
            self._kicks[h.sample] = min(bridge, fresh) * DEG
        return out

    def _vqf_terms(self, u: UncertaintyIn, i: int, bias_sd: float) -> VqfTerms:
        """VQF's σ terms at sample ``i`` of RIANN's last call (``bias_sd``: the bias estimate's σ, rad/s)."""
        s, g, h = u.samples, u.grid, u.handover
        x = s.x[i]
        b = u.bias.bias_rad_s[g.r0[i]]
        rate = math.sqrt((x[3] - b[0]) ** 2 + (x[4] - b[1]) ** 2 + (x[5] - b[2]) ** 2)
        kick = self._kicks.pop(i, None)
        if kick is None:
            kick = self._skipped(g.delta_s[i], (x[3], x[4], x[5]))
        if kick:
            self.vqf_sigma.kick(kick)
        if self._after_gap:  # started afresh: stage 6's σ of a fresh start at this sample
            self.vqf_sigma.kick(h.fresh_sd_deg[i] * DEG)
            self._after_gap = False
        return self.vqf_sigma.step(s.step_s[i], rate, math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]), bias_sd)

    def _skipped(self, span: float, w: Vec) -> float:
        """VQF's σ (rad) after a sample whose step on stage 1's timeline (de-jittered), ``span`` s, is more than
        :data:`SKIP_FACTOR` × the stream's usual: samples were lost, fewer than a hole, and the grid bridged them by
        interpolation, whose missed rotation VQF integrates (stage 6's bridge σ without its floor, from the gyro
        ``w`` here and at the previous sample); 0 where none were lost."""
        w_prev = self._w_prev
        self._w_prev = w
        if self._span_lp <= 0.0:
            self._span_lp = span
            return 0.0
        lost = span > SKIP_FACTOR * self._span_lp
        self._span_lp += (span - self._span_lp) / SPAN_SAMPLES
        if not lost:
            return 0.0
        return math.sqrt(max(bridge_sigma(w_prev, w, span) ** 2 - S_FLOOR**2, 0.0)) * DEG

    def _one(self, qr: list[float], qv: Quat, s_r: float, f: list[float], v: VqfTerms, dt: float = 0.0
             ) -> tuple[Quat, float]:
        """One sample: RIANN's output ``qr`` and σ ``s_r``, stage 8's features ``f``, VQF's attitude ``qv`` and σ
        terms ``v``, ``dt`` s since the previous sample → the output attitude and its inclination σ."""
        gr, gv = gravity((qr[0], qr[1], qr[2], qr[3])), gravity(qv)
        lag_r, hand_r = (K_BIAS * f[3]) ** 2, f[2] * f[2]
        d = _angle(gr, gv)
        self.disagreement = d
        if hand_r > 0.0:  # a hole's hand-over, or a gap's fresh network: RIANN's (module docstring)
            self.weight = 1.0
            return (qr[0], qr[1], qr[2], qr[3]), s_r
        own_r = max(s_r * s_r - v.floor - lag_r, 0.0)
        sick_r = lag_r > s_r * s_r - lag_r  # RIANN's bias lag outweighs its steady terms
        if not (sick_r or v.unhealthy):
            self._learn_scale(d, own_r + v.own + (math.sqrt(lag_r) - math.sqrt(v.bias)) ** 2, dt)
        own_r, own_v = own_r * self.scale, v.own * self.scale
        timing = (f[1] * dt * TIMING_SHARE) ** 2  # both read the same rows: a common timing error
        var_r, var_v = max(s_r * s_r, v.floor + lag_r + own_r) + timing, v.floor + v.bias + own_v + timing
        cov = v.floor + timing + math.sqrt(lag_r * v.bias) + RHO_OWN * math.sqrt(own_r * own_v)
        var_d = var_r + var_v - 2.0 * cov
        if d * d > CHI2_2_99 * var_d:  # they part by more than their σ explain
            excess = d * d / CHI2_2_99 - var_d
            if sick_r != v.unhealthy:
                var_r, var_v = (var_r + excess, var_v) if sick_r else (var_r, var_v + excess)
            else:
                var_r, var_v = var_r + excess * var_r / (var_r + var_v), var_v + excess * var_v / (var_r + var_v)
            var_d = var_r + var_v - 2.0 * cov
            w, var = _weigh(var_r, var_v, cov, var_d)
            var += w * (1.0 - w) * d * d / 2.0  # one of the two is right, as likely as its weight
        else:
            w, var = _weigh(var_r, var_v, cov, var_d)
        self.weight = w
        g = (w * gr[0] + (1.0 - w) * gv[0], w * gr[1] + (1.0 - w) * gv[1], w * gr[2] + (1.0 - w) * gv[2])
        q = tilt_to((qr[0], qr[1], qr[2], qr[3]), g)
        if q[0] < 0.0:
            q = (-q[0], -q[1], -q[2], -q[3])
        return q, math.sqrt(var)


    def _learn_scale(self, d: float, var_d: float, dt: float) -> None:
        """The own errors' scale (:attr:`scale`) from the disagreement ``d`` of a sample where both are healthy and
        the model's per-axis variance of it, ``var_d``, both low-passed over :data:`SCALE_TAUS` × ``tau_acc``."""
        if self._lp_model <= 0.0:  # the first: the model's own value for both
            self._lp_d2 = self._lp_model = 2.0 * var_d
        k = min(dt / (SCALE_TAUS * self.vqf_sigma.tau_acc), 1.0)
        self._lp_d2 += k * (d * d - self._lp_d2)
        self._lp_model += k * (2.0 * var_d - self._lp_model)
        self.scale = max(1.0, self._lp_d2 / self._lp_model) if self._lp_model > 0.0 else 1.0


def _angle(a: Vec, b: Vec) -> float:
    cx, cy, cz = a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]
    return math.atan2(math.sqrt(cx * cx + cy * cy + cz * cz), a[0] * b[0] + a[1] * b[1] + a[2] * b[2])


def _weigh(var_r: float, var_v: float, cov: float, var_d: float) -> tuple[float, float]:
    """The minimum-variance weight on RIANN and the combination's variance (module docstring), ``w`` kept in
    [0, 1]."""
    if var_d <= 1e-18:
        return 0.5, var_r
    w = (var_v - cov) / var_d
    if w <= 0.0:
        return 0.0, var_v
    if w >= 1.0:
        return 1.0, var_r
    return w, max((var_r * var_v - cov * cov) / var_d, 0.0)
