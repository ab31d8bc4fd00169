"""Stage 6, the hand-over after a hole: the inclination moves from the gyro bridge to the fresh network (ROS-free).

After a hole the *bridge* (the attitude carried across it by the interpolated gyro) is off by what the gyro did
in the hole; the *fresh network* (stage 4) starts from the accelerometer alone and is off by the linear
acceleration until it has seen enough motion. The output starts at the bridge and its gravity direction moves
toward the network's with the weight of a two-estimate fusion ``K = σ_b² / (σ_b² + σ_f(t)²)``: ``σ_b``
(:func:`bridge_sigma`) from the gyro at the hole's ends, ``σ_f(t)`` from the motion seen since, decaying with the
network's re-convergence time :data:`TAU`. The blend ends when ``K`` is within :data:`DONE` of 1. Gaps longer
than the gate's ``max_dt`` have no bridge and never blend. Physics, constants and measurements: docs/riann.md,
stage 6.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from riann_ros.constants import GRAVITY, RAD
from riann_ros.estimators.riann.stage import Cause, HandoverBlock, HandoverIn, Quat, Vec
from riann_ros.rotations import gravity, rotate, tilt_to, toward, unit

TAU = 0.5  # s: a fresh network's error decays with about this time constant after a restart in motion
S_REST = 2.0  # deg: the fresh network's starting error at rest
S_RATE = 10.0  # deg per rad/s of the fastest rotation rate seen since the hole
S_LIN = 10.0  # × the tilt (deg) that the largest | |a| - g | seen since the hole can cause
S_FLOOR = 1.0  # deg: the bridge's smallest uncertainty (the network's own error before the hole)
ROT_SHARE = 0.25  # share of the rotation at the faster end rate that the bridge may miss
DONE = 1e-3  # the blend ends when 1 - K is below this
FRESH_DONE = 0.01  # deg: after a gap, σ_f is reported until it falls below this


def bridge_sigma(w_before: Sequence[float], w_after: Sequence[float], hole_s: float) -> float:
    """Uncertainty (deg) of the gyro bridge over a hole of ``hole_s`` seconds between the rates (rad/s)
    of the samples on either side."""
    dw = math.dist(w_before, w_after)
    w = max(math.hypot(*w_before), math.hypot(*w_after))
    return math.sqrt(S_FLOOR**2 + (RAD * dw * hole_s / 2.0) ** 2 + (RAD * ROT_SHARE * w * hole_s) ** 2)


class FreshNetwork:
    """A fresh network's inclination uncertainty ``σ_f(t)`` (deg) since its start: ``S_REST`` plus what the fastest
    rotation rate and the largest | |a| − g | seen since can add, decaying with the re-convergence time
    :data:`TAU`."""

    def __init__(self, w_max: float = 0.0, acc: Vec | None = None) -> None:
        self.t = 0.0
        self.w_max = w_max
        self.lin = 0.0
        self.started = acc is not None  # its first sample seen (given here, or the first advance)
        if acc is not None:
            self._see(acc)

    def _see(self, acc: Vec) -> None:
        self.lin = max(self.lin, abs(math.sqrt(acc[0] * acc[0] + acc[1] * acc[1] + acc[2] * acc[2]) - GRAVITY))

    def advance(self, delta: Quat, dt: float, acc: Vec) -> None:
        """The next sample: bias-corrected gyro increment ``delta`` over ``dt`` s, accelerometer ``acc``. The first
        sample starts the network: no time or turn before it."""
        if not self.started:
            self.started = True
            self._see(acc)
            return
        self.t += dt
        self._see(acc)
        if dt > 0.0:
            s = math.sqrt(delta[1] * delta[1] + delta[2] * delta[2] + delta[3] * delta[3])
            self.w_max = max(self.w_max, 2.0 * math.atan2(s, abs(delta[0])) / dt)

    def sigma(self) -> float:
        """σ_f (deg) now."""
        s0 = S_REST + S_RATE * self.w_max + S_LIN * RAD * math.atan2(self.lin, GRAVITY)
        return s0 * math.exp(-self.t / TAU)


class HoleBlend:
    """The hand-over after one hole: started at the sample that ends the hole with the bridged attitude."""

    def __init__(self, sigma_b: float, q_bridge: Quat, w_max: float, acc: Vec) -> None:
        self.sb2 = sigma_b * sigma_b
        self.v = gravity(q_bridge)
        self.fresh = FreshNetwork(w_max, acc)

    def weight(self) -> float:
        """K: how far the output moves to the network's inclination at the current time."""
        sf = self.fresh.sigma()
        return self.sb2 / (self.sb2 + sf * sf)

    def sigma(self) -> float:
        """Uncertainty (deg) of the output's inclination now, as the fusion of the two estimates sees it:
        ``σ_b σ_f / √(σ_b² + σ_f²)`` (the heading stage weighs the field's heading with it)."""
        sf2 = self.fresh.sigma() ** 2
        return math.sqrt(self.sb2 * sf2 / (self.sb2 + sf2))

    def step(self, q_net: Quat, delta: Quat, dt: float, acc: Vec) -> tuple[Quat, bool]:
        """The output attitude for the next sample (network attitude ``q_net``, bias-corrected gyro increment
        ``delta`` since the previous sample over ``dt`` s) and whether the blend goes on."""
        self.fresh.advance(delta, dt, acc)
        w, x, y, z = delta
        carried = rotate((w, -x, -y, -z), self.v)  # the bridge's gravity direction in the new sensor frame
        k = self.weight()
        self.v = toward(unit(carried), gravity(q_net), k)
        if 1.0 - k < DONE:
            return q_net, False
        return tilt_to(q_net, self.v), True


class Handover:
    """Stage 6: a :class:`HoleBlend` from each hole on, while it lasts (``blend``: the ``hole_blend`` parameter).
    Every hole's bridge uncertainty is passed on for the heading stage, blend or not."""

    NAME = "handover"

    def __init__(self, blend: bool) -> None:
        self.configure(blend)
        self.restart(Cause.RESET)

    def configure(self, blend: bool) -> None:
        """``hole_blend``: hand over after a hole (else the fresh network's output at once)."""
        self.enabled = blend

    def restart(self, cause: Cause) -> None:
        """GAP: the blend ends, a gap's fresh network starts; RESET: both end."""
        self.blend: HoleBlend | None = None
        # after a gap the output is the fresh network itself: its σ_f until it is negligible, for stage 8 only (the
        # attitude and the heading's weighting are not touched); after a reset the bias front end starts anew and its
        # σ already covers the fresh network's
        self.fresh: FreshNetwork | None = FreshNetwork() if cause is Cause.GAP else None

    def run(self, block: HandoverIn) -> HandoverBlock:
        """The attitudes after the hand-over, each sample's inclination σ while a hand-over runs (deg; 0 where none
        runs), the fresh network's σ after a gap, and per sample that ends a hole the σ of its bridge (deg)."""
        s, holes = block.samples, block.grid.holes
        qc, delta, dt = list(block.carry.q), block.carry.delta, s.step_s
        acc = [(r[0], r[1], r[2]) for r in s.x]
        starts = {}
        for h in holes:
            w_max = max(math.hypot(*h.w_before_rad_s), math.hypot(*h.w_after_rad_s))
            starts[h.sample] = (bridge_sigma(h.w_before_rad_s, h.w_after_rad_s, h.length_s), w_max)
        fresh_sd = self._fresh_sd(delta, dt, acc, min(starts, default=len(qc)))
        sd = [0.0] * len(qc)
        i = 0 if self.blend is not None else min(starts, default=len(qc))
        while i < len(qc):
            b = starts.get(i)
            if b is None and self.blend is None:
                i = min((h for h in starts if h > i), default=len(qc))
                continue
            if b is not None and self.enabled:
                self.blend = HoleBlend(b[0], qc[i], b[1], acc[i])
            elif self.blend is not None:
                q, going = self.blend.step(qc[i], delta[i], dt[i], acc[i])
                qc[i] = q
                if not going:
                    self.blend = None
            if self.blend is not None:
                sd[i] = self.blend.sigma()
            i += 1
        return HandoverBlock(qc, sd, fresh_sd, {k: v[0] for k, v in starts.items()})

    def _fresh_sd(self, delta: list[Quat], dt: list[float], acc: list[Vec], end: int) -> list[float]:
        """Each sample's σ_f (deg) while a fresh network started by a gap is young (0 elsewhere), up to ``end``
        (the next hole's sample: a blend takes over from there)."""
        sd = [0.0] * len(delta)
        fresh = self.fresh
        i = 0
        while fresh is not None and i < end:
            fresh.advance(delta[i], dt[i], acc[i])
            sd[i] = fresh.sigma()
            if sd[i] < FRESH_DONE:
                fresh = None
            i += 1
        self.fresh = fresh if end >= len(delta) else None
        return sd

    def diagnostics(self) -> dict[str, str]:
        return {}
