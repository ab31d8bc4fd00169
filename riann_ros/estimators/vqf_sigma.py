"""VQF's inclination σ from its state, instead of a constant (ROS-free).

VQF (Laidig & Seel 2023) corrects the gyro's inclination toward the accelerometer's through a low-pass of time
constant ``τ_acc`` (``tau_acc``). What its error is made of follows from that (per horizontal axis)::

    σ_V² = σ₀² + (k_b·σ_b)² + (k_ω·ω̄)² + (k_a·ā)² + x²

* ``σ₀`` — the floor: what every accelerometer-based inclination shares (the accelerometer's own bias and
  misalignment; against a reference also the reference's alignment). RIANN's stage 8 floor
  (:data:`~.riann.s8_uncertainty.SIGMA0`), the same sensor's.
* ``k_b·σ_b`` — a gyro-bias error ``b`` drifts the gyro's inclination at ``b`` and the correction pulls it back
  with time constant ``τ_acc``: the lag is ``b·τ_acc`` about the bias's horizontal component. ``σ_b`` is the σ of
  the bias estimate (VQF's own, or the front end's that removed it), VQF's *worst* direction, which in motion is
  mostly the least observable one: so ``k_b`` is fitted (0.34 s, well below ``τ_acc``).
* ``k_ω·ω̄`` and ``k_a·ā`` — what the motion does: ``ω̄`` the rotation rate (bias removed) low-passed over
  :data:`TAU_MOTION` (stage 8's), ``ā = √(LP_τacc((|a| − g)²))/g`` the RMS of the specific force's deviation from
  gravity over the filter's window (the linear acceleration the low-pass has to average out, seen through its norm).

``k_b``, ``k_ω`` and ``k_a`` are fitted by maximum likelihood on synthetic sensors of five grades and three motions
(``bench/fit_consensus.py``), never on the shared BROAD trials; on those the σ holds (docs/consensus.md).
* ``x`` — a transient: after a hole the gyro bridged (its σ from the gyro at the hole's ends, stage 6's bound) or
  after a restart from the accelerometer (a gap), decaying as the correction pulls it in: ``x = x₀·exp(−t/τ_acc)``.

:class:`VqfSigma` keeps the low-passes and the transient per sample in plain floats (the node's call is one sample).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from riann_ros.constants import DEG, GRAVITY
from riann_ros.estimators.base import Array
from riann_ros.estimators.riann.s6_handover import FreshNetwork
from riann_ros.estimators.riann.s8_uncertainty import SIGMA0, TAU_MOTION

# fitted on synthetic sensors (bench/fit_consensus.py); the other terms are physics (module docstring)
K_LAG = 0.335  # s: rad of tilt per rad/s of the bias estimate's σ
K_RATE = 0.0009  # s: rad of tilt per rad/s of low-passed rotation rate
K_ACC = 0.032  # rad of tilt per unit of RMS specific-force deviation (in g)
TRANSIENT_END = 1e-4  # rad: a transient below this is over


class VqfTerms(NamedTuple):
    """One sample's σ_V² split as the combination needs it (rad²): the floor (common to every accelerometer-based
    inclination), the bias lag (its sign common to RIANN's), and VQF's own: the rotation's share (steady) and what
    says its state is not healthy: the linear acceleration's share and the transient."""

    floor: float
    bias: float
    rate: float
    acc: float
    transient: float

    @property
    def total(self) -> float:
        return self.floor + self.bias + self.rate + self.acc + self.transient

    @property
    def own(self) -> float:
        """VQF's own share (not common to RIANN's)."""
        return self.rate + self.acc + self.transient

    @property
    def unhealthy(self) -> bool:
        """The bias lag, the linear acceleration and the transient outweigh the steady terms."""
        return self.bias + self.acc + self.transient > self.floor + self.rate


class VqfSigma:
    """The σ model's state (module docstring): the motion low-passes and the transient."""

    def __init__(self, tau_acc: float) -> None:
        self.tau_acc = tau_acc
        self.reset()

    def reset(self) -> None:
        self.rate_lp = 0.0  # rad/s
        self.acc_lp = 0.0  # (|a| − g)² low-passed, in g²
        self.started = False
        self.transient = 0.0  # rad

    def kick(self, sd_rad: float) -> None:
        """A hole's bridge or a restart leaves VQF's attitude off by about ``sd_rad``."""
        self.transient = math.hypot(self.transient, sd_rad)

    def step(self, dt: float, rate: float, acc_norm: float, bias_sd: float) -> VqfTerms:
        """One sample: ``dt`` s since the previous one, the rotation rate ``rate`` (rad/s, bias removed), the
        specific force's norm ``acc_norm`` (m/s²) and the σ of the gyro-bias estimate ``bias_sd`` (rad/s)."""
        dev = (acc_norm / GRAVITY - 1.0) ** 2
        if self.started:
            self.rate_lp += min(dt / TAU_MOTION, 1.0) * (rate - self.rate_lp)
            self.acc_lp += min(dt / self.tau_acc, 1.0) * (dev - self.acc_lp)
            if self.transient:
                self.transient *= math.exp(-dt / self.tau_acc)
                if self.transient < TRANSIENT_END:
                    self.transient = 0.0
        else:
            self.rate_lp, self.acc_lp, self.started = rate, dev, True
        lag = K_LAG * bias_sd
        return VqfTerms(SIGMA0 * SIGMA0, lag * lag, (K_RATE * self.rate_lp) ** 2, K_ACC * K_ACC * self.acc_lp,
                        self.transient**2)


class VqfStateSigma:
    """The σ model over the samples :class:`~.vqf_estimator.VqfEstimator` ran (its ``sigma_model`` 'state'): VQF's
    own bias estimate and its σ after each sample, and from its start the σ of a filter started from the
    accelerometer alone (stage 6's :class:`~.riann.s6_handover.FreshNetwork` at the first sample), decaying with
    ``tau_acc``."""

    def __init__(self, tau_acc: float) -> None:
        self.model = VqfSigma(tau_acc)
        self.sigma: list[float] = []

    def take(self, acc: Array, gyr: Array, dt: Array, bias: Array, bias_sd: Array) -> None:
        """The samples of one call: ``gyr`` as VQF integrated it, ``bias`` and ``bias_sd`` VQF's after each."""
        m = self.model
        a, w, d, s = acc.tolist(), (gyr - bias).tolist(), dt.tolist(), bias_sd.tolist()
        out = []
        for k in range(len(a)):
            ax, ay, az = a[k]
            if not m.started:
                m.kick(FreshNetwork(0.0, (ax, ay, az)).sigma() * DEG)
            t = m.step(d[k], math.sqrt(w[k][0] ** 2 + w[k][1] ** 2 + w[k][2] ** 2),
                       math.sqrt(ax * ax + ay * ay + az * az), s[k])
            out.append(math.sqrt(t.total))
        self.sigma = out

    def last(self, n: int) -> Array:
        """σ (rad) of the ``n`` samples of the last call."""
        if len(self.sigma) != n:
            raise ValueError(f"sigma for {n} samples asked, the last call had {len(self.sigma)}")
        return np.asarray(self.sigma)
