"""Seeded synthetic IMU recordings with exact ground truth.

The sensor orientation is ``q(t) = qz(ψ) ⊗ qy(θ) ⊗ qx(φ)`` (sensor → world, world z up) with Euler
angles that are smooth random functions (sums of sinusoids) of a *motion clock* ``τ(t)``. The clock
runs at speed ``e(t)`` ∈ [0, 1]: 0 in rest phases, 1 in movement phases, with raised-cosine ramps
between them, so rest phases are exactly still and everything is C¹ smooth. The position is another
sum of sinusoids of ``τ``. All derivatives are analytic, so:

* ``gyr = ω_body(t) + bias + noise`` with the exact body angular velocity
  ``ω = [φ̇ − ψ̇ sinθ, θ̇ cosφ + ψ̇ sinφ cosθ, −θ̇ sinφ + ψ̇ cosφ cosθ]``;
* ``acc = Rᵀ (a_world + [0, 0, g]) + noise`` (specific force in the sensor frame);
* ``quat_ref = q(t)`` exactly, at every sample; ``score_mask`` = movement phases (``e(t) > 0``).

Tolerance (tested): integrating the noise-free, bias-free gyroscope with the trapezoidal rule
(``q ← q ⊗ exp(½(ω_k + ω_{k+1})·dt)``) reproduces the ground truth within 0.1° after 60 s at 200 Hz
(the error is the O(dt²) integration error); with noise the random-walk adds ≈ σ·√(dt·T).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from riann_ros import defaults
from riann_ros import quaternion as quat
from riann_ros.constants import GRAVITY, NS_PER_S
from riann_ros.recording import Recording

MOTIONS = ("combined", "rotation", "translation")
SOURCE = "riann_ros synthetic generator (riann_ros.datasets.synthetic), exact ground truth"


@dataclass
class _Sines:
    """f(τ) = Σ a_k sin(w_k τ + p_k) per output column; analytic first and second derivative."""

    amp: np.ndarray  # (K, D)
    omega: np.ndarray  # (K, D)
    phase: np.ndarray  # (K, D)

    def __call__(self, tau: np.ndarray, order: int = 0) -> np.ndarray:
        arg = tau[:, None, None] * self.omega[None] + self.phase[None]
        if order == 0:
            v = self.amp * np.sin(arg)
        elif order == 1:
            v = self.amp * self.omega * np.cos(arg)
        else:
            v = -self.amp * self.omega**2 * np.sin(arg)
        return v.sum(axis=1)


def _random_sines(rng: np.random.Generator, dims: int, k: int, amp: np.ndarray, fmin: float, fmax: float) -> _Sines:
    a = rng.uniform(0.3, 1.0, (k, dims)) * np.asarray(amp, dtype=float)[None, :] / np.sqrt(k)
    w = 2 * np.pi * rng.uniform(fmin, fmax, (k, dims))
    p = rng.uniform(0, 2 * np.pi, (k, dims))
    return _Sines(a, w, p)


def _phases(rng: np.random.Generator, duration: float, ramp: float) -> list[tuple[float, float]]:
    """Movement phases (start, end) in seconds: rest 2–4 s, movement 6–15 s, alternating."""
    phases = []
    t = rng.uniform(2.0, 4.0)
    while t + 2 * ramp + 1.0 < duration - 2.0:
        length = min(rng.uniform(6.0, 15.0), duration - 2.0 - t)
        phases.append((t, t + length))
        t += length + rng.uniform(2.0, 4.0)
    return phases


def _clock(t: np.ndarray, phases: list[tuple[float, float]], ramp: float):
    """Motion clock τ(t), its speed e(t) = τ̇ and ė(t) for raised-cosine ramps of length ``ramp``."""
    tau = np.zeros_like(t)
    e = np.zeros_like(t)
    de = np.zeros_like(t)
    for a, b in phases:
        r = min(ramp, 0.5 * (b - a))
        k = np.pi / r
        full = (b - a) - r  # integral of e over a complete phase (two ramps of r/2 each + flat part)
        s_up = t - a
        s_dn = b - t
        up = (s_up >= 0) & (s_up < r)
        flat = (s_up >= r) & (s_dn > r)
        dn = (s_dn > 0) & (s_dn <= r)
        after = s_dn <= 0
        e[up] += 0.5 * (1 - np.cos(k * s_up[up]))
        de[up] += 0.5 * k * np.sin(k * s_up[up])
        tau[up] += 0.5 * (s_up[up] - np.sin(k * s_up[up]) / k)
        e[flat] += 1.0
        tau[flat] += 0.5 * r + (s_up[flat] - r)
        e[dn] += 0.5 * (1 - np.cos(k * s_dn[dn]))
        de[dn] -= 0.5 * k * np.sin(k * s_dn[dn])
        tau[dn] += full - 0.5 * (s_dn[dn] - np.sin(k * s_dn[dn]) / k)
        tau[after] += full
    return tau, e, de


def body_rate(euler: np.ndarray, deuler: np.ndarray) -> np.ndarray:
    """Body-frame angular velocity of ``qz(ψ) ⊗ qy(θ) ⊗ qx(φ)``; columns φ, θ, ψ."""
    phi, th = euler[:, 0], euler[:, 1]
    dphi, dth, dpsi = deuler[:, 0], deuler[:, 1], deuler[:, 2]
    return np.stack(
        [
            dphi - dpsi * np.sin(th),
            dth * np.cos(phi) + dpsi * np.sin(phi) * np.cos(th),
            -dth * np.sin(phi) + dpsi * np.cos(phi) * np.cos(th),
        ],
        axis=1,
    )


def euler_to_quat(euler: np.ndarray) -> np.ndarray:
    """``qz(ψ) ⊗ qy(θ) ⊗ qx(φ)`` as w, x, y, z; columns φ, θ, ψ."""
    z = np.zeros(len(euler))
    qx = np.stack([np.cos(euler[:, 0] / 2), np.sin(euler[:, 0] / 2), z, z], axis=1)
    qy = np.stack([np.cos(euler[:, 1] / 2), z, np.sin(euler[:, 1] / 2), z], axis=1)
    qz = np.stack([np.cos(euler[:, 2] / 2), z, z, np.sin(euler[:, 2] / 2)], axis=1)
    return quat.multiply(quat.multiply(qz, qy), qx)


def _check(motion: str, rate: float, duration: float, gyr_noise: float, acc_noise: float) -> None:
    """ValueError for settings no recording can be made from."""
    if motion not in MOTIONS:
        raise ValueError(f"unknown motion {motion!r}; expected one of {', '.join(MOTIONS)}")
    if not (rate > 0 and np.isfinite(rate)):
        raise ValueError(f"rate must be positive, got {rate}")
    if not (duration > 0 and np.isfinite(duration)):
        raise ValueError(f"duration must be positive, got {duration}")
    if gyr_noise < 0 or acc_noise < 0:
        raise ValueError("noise standard deviations must be >= 0")


def _rotation(rng: np.random.Generator, tau: np.ndarray, e: np.ndarray, motion: str, max_tilt_deg: float,
              speed: float) -> tuple[np.ndarray, np.ndarray]:
    """The attitude ``q(t)`` (w ≥ 0) and the exact body rate ``ω(t)`` of seeded Euler angles of the clock ``τ``."""
    tilt = np.deg2rad(max_tilt_deg) * (0.25 if motion == "translation" else 1.0)
    rot = _random_sines(rng, 3, 4, np.array([tilt, tilt, 2.5 * tilt]), 0.05 * speed, 0.4 * speed)
    base = rng.uniform(-np.pi, np.pi, 3) * np.array([0.2, 0.2, 1.0])
    euler = base + rot(tau)
    deuler = rot(tau, 1) * e[:, None]
    q = euler_to_quat(euler)
    return q * np.where(q[:, :1] < 0, -1.0, 1.0), body_rate(euler, deuler)


def _translation(rng: np.random.Generator, tau: np.ndarray, e: np.ndarray, de: np.ndarray, motion: str,
                 speed: float) -> np.ndarray:
    """The world-frame linear acceleration (N, 3) of a seeded position of the clock ``τ`` (zero for rotation)."""
    if motion == "rotation":
        return np.zeros((len(tau), 3))
    amp = np.array([0.3, 0.3, 0.15]) * (1.5 if motion == "translation" else 1.0)
    pos = _random_sines(rng, 3, 3, amp, 0.15 * speed, 0.8 * speed)
    # p(t) = P(τ(t)) → a = P''(τ) e² + P'(τ) ė
    return pos(tau, 2) * (e**2)[:, None] + pos(tau, 1) * de[:, None]


def _gyro_bias(rng: np.random.Generator, bias: float | tuple[float, float, float]) -> np.ndarray:
    """The constant gyro bias: a 3-vector as given, or a magnitude along a seeded random direction."""
    if np.ndim(bias) == 0:
        d = rng.normal(size=3)
        return float(bias) * d / np.linalg.norm(d)  # type: ignore[arg-type]
    return np.asarray(bias, dtype=float).reshape(3)


def generate(
    *,
    rate: float = defaults.SYNTHETIC.rate,
    duration: float = defaults.SYNTHETIC.duration,
    seed: int = defaults.SYNTHETIC.seed,
    motion: str = defaults.SYNTHETIC.motion,
    bias: float | tuple[float, float, float] = defaults.SYNTHETIC.bias,
    gyr_noise: float = defaults.SYNTHETIC.gyr_noise,
    acc_noise: float = defaults.SYNTHETIC.acc_noise,
    max_tilt_deg: float = defaults.SYNTHETIC.max_tilt_deg,
    speed: float = defaults.SYNTHETIC.speed,
    start_s: float = 0.0,
    name: str | None = None,
    frame_id: str = defaults.IMU_FRAME,
) -> Recording:
    """A synthetic recording (see module docstring).

    ``rate`` Hz, ``duration`` s; ``seed`` makes it reproducible. ``motion``: ``combined`` (rotation and
    translation), ``rotation`` (no translation) or ``translation`` (small tilts, large translation).
    ``bias``: constant gyro bias, rad/s — a 3-vector, or a magnitude for a seeded random direction.
    ``gyr_noise`` rad/s and ``acc_noise`` m/s²: white-noise standard deviations per sample.
    ``max_tilt_deg``: roll/pitch amplitude scale; ``speed``: frequency scale of the motion.
    """
    _check(motion, rate, duration, gyr_noise, acc_noise)
    rng = np.random.default_rng(seed)  # drawn from in this order: phases, rotation, translation, bias, noise
    n = int(np.floor(duration * rate)) + 1
    stamps = np.round(start_s * NS_PER_S + np.arange(n) * (NS_PER_S / rate)).astype(np.int64)
    t = (stamps - stamps[0]) * 1e-9
    ramp = 1.0
    tau, e, de = _clock(t, _phases(rng, float(t[-1]), ramp), ramp)
    q, w = _rotation(rng, tau, e, motion, max_tilt_deg, speed)
    f_world = _translation(rng, tau, e, de, motion, speed) + np.array([0.0, 0.0, GRAVITY])
    b = _gyro_bias(rng, bias)
    acc = quat.rotate(quat.conjugate(q), f_world) + acc_noise * rng.normal(size=(n, 3))
    gyr = w + b + gyr_noise * rng.normal(size=(n, 3))
    meta = {"seed": str(seed), "rate_hz": repr(float(rate)), "duration_s": repr(float(duration)), "motion": motion,
            "gyr_bias_rad_s": " ".join(repr(float(x)) for x in b), "gyr_noise_rad_s": repr(float(gyr_noise)),
            "acc_noise_m_s2": repr(float(acc_noise)), "max_tilt_deg": repr(float(max_tilt_deg)),
            "speed": repr(float(speed))}
    return Recording(stamps_ns=stamps, acc=acc, gyr=gyr, quat_ref=q, score_mask=e > 0,
                     name=name or f"synthetic_{motion}_seed{seed}_{rate:g}hz", dataset="synthetic", source=SOURCE,
                     frame_id=frame_id, meta=meta)


def integrate_gyr(gyr: np.ndarray, stamps_ns: np.ndarray, q0: np.ndarray) -> np.ndarray:
    """Strapdown integration with the trapezoidal rule, ``q_{k+1} = q_k ⊗ exp(½(ω_k + ω_{k+1})·dt)``."""
    dt = np.diff(stamps_ns) * 1e-9
    steps = quat.from_rotvec(0.5 * (gyr[1:] + gyr[:-1]) * dt[:, None])
    out = np.empty((len(gyr), 4))
    out[0] = q0
    q = np.asarray(q0, dtype=float)
    for k in range(len(steps)):
        q = quat.multiply(q, steps[k])
        out[k + 1] = q
    return quat.normalize(out)
