"""After a hole in the stream: hand the inclination over from the gyro bridge to the fresh network (ROS-free).

During a hole (messages lost while the sensor moves) the rotation is unknown. Two estimates of the
inclination exist after it, and each is wrong in its own way:

* the **bridge** — the attitude before the hole carried across it by the gyro interpolated between the
  samples on either side — is off by what the gyro did in between: little when the sensor translates or
  turns steadily, tens of degrees after a 0.4 s hole in a fast swing;
* a **fresh network** (the running one trusts its integrated state and would keep the bridge's error for
  seconds, so RIANN restarts it after a hole) starts from the accelerometer alone. At rest that is
  gravity and it is right within a row or two; in motion it is gravity plus the linear acceleration, and
  the fresh state is off by tens of degrees — over 100° in fast translation — until it has seen enough
  motion to separate the two (about half a second).

The output therefore starts at the bridge and moves toward the fresh network's inclination with the
weight of a two-estimate fusion, ``K = σ_b² / (σ_b² + σ_f(t)²)``:

* ``σ_b`` (deg), the bridge's uncertainty, is set once at the hole from what the gyro says about it: the
  rate change across the hole times half its length (the trapezoid bridge is exact for a rate that
  changes linearly) and a quarter of the rotation the faster of the two rates would make over the hole
  (what the rate may have done in between), with a floor of 1°;
* ``σ_f(t)`` (deg), the fresh network's, decays with the network's re-convergence time ``TAU`` from a
  start that grows with the motion seen since the hole: 2° at rest, plus 10° per rad/s of rotation rate
  and 10× the tilt that the linear acceleration seen (| |a| − g |, a lower bound of it) can cause.

Each sample the blended gravity direction is carried on by the sample's bias-corrected gyro increment
and moved toward the network's by ``K``; the output's inclination is the blended one (the smallest
rotation of the network attitude that gives it that gravity direction), heading handled after it as
everywhere. The blend ends when ``K`` is within ``DONE`` of 1: from then on the output is the network's
again, exactly. Gaps longer than the input gate's ``max_dt`` are not bridged at all (the estimator
restarts without a bridge) and never blend.

Measured on the 12 BROAD trials with holes of 0.1–0.6 s every ~10 s, and why these constants: see
``docs/riann.md`` §3 ("hand-over after a hole").
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from riann_ros.estimators.heading import _rotate, qmul

Quat = tuple[float, float, float, float]
Vec = tuple[float, float, float]

DEG = 180.0 / math.pi
G = 9.81  # m/s²
TAU = 0.5  # s: a fresh network's error decays with about this time constant after a restart in motion
S_REST = 2.0  # deg: the fresh network's starting error at rest
S_RATE = 10.0  # deg per rad/s of the fastest rotation rate seen since the hole
S_LIN = 10.0  # × the tilt (deg) that the largest | |a| - g | seen since the hole can cause
S_FLOOR = 1.0  # deg: the bridge's smallest uncertainty (the network's own error before the hole)
ROT_SHARE = 0.25  # share of the rotation at the faster end rate that the bridge may miss
DONE = 1e-3  # the blend ends when 1 - K is below this


def bridge_sigma(w_before: Sequence[float], w_after: Sequence[float], hole_s: float) -> float:
    """Uncertainty (deg) of the gyro bridge over a hole of ``hole_s`` seconds between the rates (rad/s)
    of the samples on either side."""
    dw = math.dist(w_before, w_after)
    w = max(math.hypot(*w_before), math.hypot(*w_after))
    return math.sqrt(S_FLOOR**2 + (DEG * dw * hole_s / 2.0) ** 2 + (DEG * ROT_SHARE * w * hole_s) ** 2)


def gravity(q: Quat) -> Vec:
    """World z (up) in the sensor frame of the sensor-to-world attitude ``q``: R(q)ᵀ e_z."""
    w, x, y, z = q
    return (2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y))


def _unit(v: Vec) -> Vec:
    n = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    return (v[0] / n, v[1] / n, v[2] / n)


def _toward(a: Vec, b: Vec, k: float) -> Vec:
    """Unit vector ``a`` turned toward unit vector ``b`` by the fraction ``k`` of the angle between them."""
    c = max(-1.0, min(1.0, a[0] * b[0] + a[1] * b[1] + a[2] * b[2]))
    th = math.acos(c)
    s = math.sin(th)
    if s < 1e-9:  # the same direction, or opposite (no unique path): the network's
        return b
    fa, fb = math.sin((1.0 - k) * th) / s, math.sin(k * th) / s
    return _unit((fa * a[0] + fb * b[0], fa * a[1] + fb * b[1], fa * a[2] + fb * b[2]))


def tilt_to(q: Quat, v: Vec) -> Quat:
    """``q`` turned by the smallest rotation that makes its gravity direction :func:`gravity` equal ``v``
    (about a horizontal axis: the heading of ``q`` is kept)."""
    u = gravity(q)
    ax = (u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0])
    s = math.sqrt(ax[0] * ax[0] + ax[1] * ax[1] + ax[2] * ax[2])
    if s < 1e-12:
        return q
    a = math.atan2(s, u[0] * v[0] + u[1] * v[1] + u[2] * v[2])
    h = -math.sin(0.5 * a) / s
    return qmul(q, (math.cos(0.5 * a), ax[0] * h, ax[1] * h, ax[2] * h))  # q ⊗ r⁻¹, r takes u to v in the sensor frame


class HoleBlend:
    """The hand-over after one hole: started at the sample that ends the hole with the bridged attitude."""

    def __init__(self, sigma_b: float, q_bridge: Quat, w_max: float, acc: Vec) -> None:
        self.sb2 = sigma_b * sigma_b
        self.v = gravity(q_bridge)
        self.t = 0.0
        self.w_max = w_max
        self.lin = 0.0
        self._see(acc)

    def _see(self, acc: Vec) -> None:
        self.lin = max(self.lin, abs(math.sqrt(acc[0] * acc[0] + acc[1] * acc[1] + acc[2] * acc[2]) - G))

    def _sf(self) -> float:
        """σ_f(t) (deg), the fresh network's uncertainty now."""
        s0 = S_REST + S_RATE * self.w_max + S_LIN * DEG * math.atan2(self.lin, G)
        return s0 * math.exp(-self.t / TAU)

    def weight(self) -> float:
        """K: how far the output moves to the network's inclination at the current time."""
        sf = self._sf()
        return self.sb2 / (self.sb2 + sf * sf)

    def sigma(self) -> float:
        """Uncertainty (deg) of the output's inclination now, as the fusion of the two estimates sees it:
        ``σ_b σ_f / √(σ_b² + σ_f²)`` (the heading stage weighs the field's heading with it)."""
        sf2 = self._sf() ** 2
        return math.sqrt(self.sb2 * sf2 / (self.sb2 + sf2))

    def step(self, q_net: Quat, delta: Quat, dt: float, acc: Vec) -> tuple[Quat, bool]:
        """The output attitude for the next sample (network attitude ``q_net``, bias-corrected gyro increment
        ``delta`` since the previous sample over ``dt`` s) and whether the blend goes on."""
        self.t += dt
        self._see(acc)
        if dt > 0.0:
            s = math.sqrt(delta[1] * delta[1] + delta[2] * delta[2] + delta[3] * delta[3])
            self.w_max = max(self.w_max, 2.0 * math.atan2(s, abs(delta[0])) / dt)
        w, x, y, z = delta
        carried = _rotate((w, -x, -y, -z), self.v)  # the bridge's gravity direction in the new sensor frame
        k = self.weight()
        self.v = _toward(_unit(carried), gravity(q_net), k)
        if 1.0 - k < DONE:
            return q_net, False
        return tilt_to(q_net, self.v), True
