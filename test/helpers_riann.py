"""Streams and readings shared by RIANN's tests (test_riann_*.py)."""

from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np

from riann_ros import quaternion as quat
from riann_ros.constants import GRAVITY
from riann_ros.estimators.riann import RiannEstimator
from riann_ros.estimators.riann.s1_timeline import Timeline
from riann_ros.estimators.riann.stage import Samples
from riann_ros.evaluation.scoring import roll_pitch_deg

G = GRAVITY  # m/s²: the synthetic streams' gravity
AT_REST = (0.0, 0.0, G, 0.0, 0.0, 0.0)


class RateTracker:
    """Stage 1 (the timeline) driven by input steps alone: the first step starts it, each further one is pushed (no
    holes: restart_gap 0)."""

    def __init__(self, first_dt: float, means: bool | None = None) -> None:
        self.tl = Timeline(0.0, "auto" if means is None else "means" if means else "points")
        self.tl.run(Samples.of([AT_REST], [first_dt]))

    def push(self, d: float, gyr: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> bool:
        return self.tl.run(Samples.of([(*AT_REST[:3], *gyr)], [d])).switched[0]

    def __getattr__(self, name: str):
        tl = self.tl
        return {"switches": lambda: tl.steps.switches, "step": lambda: tl.steps.step,
                "median": lambda: tl.steps.median, "jittery": lambda: tl.steps.jittery,
                "model_test": lambda: tl.model, "irregular": lambda: tl.irregular, "means": lambda: tl.means,
                "clocked": lambda: tl.clock.clocked, "mean_step": lambda: tl.clock.period(tl.steps.median),
                "variance_ratio": lambda: tl.clock.variance_ratio, "box_width": lambda: tl.box_width}[name]()


def receive_stamps(n: int, period: float, max_delay: float, seed: int = 0) -> np.ndarray:
    """Stamps (s) of samples taken every ``period`` and stamped on arrival, a uniform 0..max_delay later
    (kept in order, at least 1 µs apart)."""
    rng = np.random.default_rng(seed)
    t = period * np.arange(1, n + 1) + rng.uniform(0.0, max_delay, n)
    k = 1e-6 * np.arange(n)
    return np.maximum.accumulate(t - k) + k


def fifo_stamps(n: int, period: float, batch: int) -> np.ndarray:
    """Stamps (s) of samples taken every ``period`` and read out of a FIFO ``batch`` at a time, each batch
    stamped on arrival (when its last sample is taken), its messages 10 µs apart."""
    i = np.arange(n)
    last = np.minimum((i // batch + 1) * batch - 1, n - 1)
    return period * (last + 1) + 1e-5 * (i - last)


def tilted_rest(n: int, tilt_deg: float = 20.0) -> tuple[np.ndarray, np.ndarray]:
    q_true = quat.from_rotvec([math.radians(tilt_deg), 0.0, 0.0])
    acc = quat.rotate(quat.conjugate(q_true), [0.0, 0.0, G])
    return np.tile(acc, (n, 1)), q_true


def swing(rate_hz: float, means: bool, seconds: float = 20.0) -> tuple[np.ndarray, ...]:
    """A 1 Hz, 60° roll swing sampled at ``rate_hz``: point samples at the stamps, or interval means over
    the preceding step (the gyro's mean is exact; the accelerometer's is averaged on a fine grid)."""
    a, w = math.radians(60.0), 2 * math.pi * 1.0
    d = 1.0 / rate_hz
    t = d * np.arange(1, int(seconds * rate_hz) + 1)

    def roll(tt: np.ndarray) -> np.ndarray:
        return a * np.sin(w * tt)

    if means:
        gx = (roll(t) - roll(t - d)) / d
        fine = t[:, None] - d * (np.arange(64) + 0.5)[None, :] / 64
        acc = np.stack([np.zeros_like(t), (G * np.sin(roll(fine))).mean(1), (G * np.cos(roll(fine))).mean(1)], 1)
    else:
        gx = a * w * np.cos(w * t)
        acc = np.stack([np.zeros_like(t), G * np.sin(roll(t)), G * np.cos(roll(t))], 1)
    gyr = np.stack([gx, np.zeros_like(t), np.zeros_like(t)], 1)
    return acc, gyr, np.full(len(t), d), roll(t)


def roll_rmse(est: RiannEstimator, acc: np.ndarray, gyr: np.ndarray, dt: np.ndarray, truth: np.ndarray) -> float:
    """Roll RMSE (°) of ``est`` against ``truth`` (rad) over the last three quarters of the stream."""
    r = roll_pitch_deg(est.update_batch(acc, gyr, dt))[:, 0]
    e = np.remainder(r - np.degrees(truth) + 180.0, 360.0) - 180.0
    return float(np.sqrt(np.mean(e[len(e) // 4:] ** 2)))


def lead_of(model: str, acc: np.ndarray, gyr: np.ndarray, dt: np.ndarray, **kw: float) -> float:
    """How far (ms) RIANN's roll leads a 1 Hz swing (:func:`swing`, :func:`jittered_swing`): the phase of the
    sinusoid fitted to the estimate over the last three quarters of the stream, as time (positive: early)."""
    r = roll_pitch_deg(RiannEstimator(input_model=model, gyro_bias_estimation=False, **kw).update_batch(acc, gyr, dt))
    t = np.cumsum(dt)
    k = len(t) // 4
    w = 2 * math.pi
    (a, b), *_ = np.linalg.lstsq(np.column_stack([np.sin(w * t[k:]), np.cos(w * t[k:])]), r[k:, 0], rcond=None)
    return 1e3 * math.atan2(b, a) / w


@functools.cache
def straight_lead_ms() -> float:
    """The network's own lead on ideal point samples fed straight in (200 Hz, one row per sample): about 5 ms,
    learnt from real sensors whose samples lag the motion by their filter's delay."""
    return lead_ms("points", data_means=False, rate=200.0)


def lead_ms(model: str, data_means: bool, rate: float, **kw: float) -> float:
    """:func:`lead_of` on the regular swing of :func:`swing`."""
    return lead_of(model, *swing(rate, data_means)[:3], **kw)


def jittered_swing(means: bool, seconds: float = 30.0, seed: int = 0) -> tuple[np.ndarray, ...]:
    """The 1 Hz, 60° roll swing sampled at random times 10, 20 or 30 ms apart: point samples at the stamps,
    or interval means over the preceding interval (gyro exact, accelerometer averaged on a fine grid)."""
    a, w = math.radians(60.0), 2 * math.pi * 1.0
    dt = np.random.default_rng(seed).choice([0.010, 0.020, 0.030], size=int(seconds / 0.020))
    t = np.cumsum(dt)

    def roll(tt: np.ndarray) -> np.ndarray:
        return a * np.sin(w * tt)

    if means:
        gx = (roll(t) - roll(t - dt)) / dt
        fine = t[:, None] - dt[:, None] * (np.arange(64) + 0.5)[None, :] / 64
        acc = np.stack([np.zeros_like(t), (G * np.sin(roll(fine))).mean(1), (G * np.cos(roll(fine))).mean(1)], 1)
    else:
        gx = a * w * np.cos(w * t)
        acc = np.stack([np.zeros_like(t), G * np.sin(roll(t)), G * np.cos(roll(t))], 1)
    return acc, np.stack([gx, np.zeros_like(t), np.zeros_like(t)], 1), dt, roll(t)


def hole_stream(restart_gap: float) -> tuple[RiannEstimator, np.ndarray, np.ndarray]:
    """Level rest at 200 Hz, a 0.4 s hole during which the sensor was tilted by 40°, tilted rest after."""
    n0, n1 = 200 * 20, 200 * 3
    acc0 = np.tile([0.0, 0.0, G], (n0, 1))
    acc1, q_true = tilted_rest(n1, 40.0)
    acc = np.vstack([acc0, acc1])
    dt = np.full(n0 + n1, 0.005)
    dt[n0] = 0.4
    est = RiannEstimator(restart_gap=restart_gap, gyro_bias_estimation=False)
    q = est.update_batch(acc, np.zeros((n0 + n1, 3)), dt)
    t_after = np.cumsum(dt[n0:]) - dt[n0]
    err = np.degrees(quat.inclination_error(q_true, q[n0:]))
    return est, t_after, err


def shaken_with_a_hole(rate: float = 200.0, hole: float = 0.3) -> tuple[np.ndarray, ...]:
    """A sensor held at 20° roll and shaken along world x (6 m/s², 1.5 Hz) without turning, with a hole of
    ``hole`` s at 10 s: the accelerometer alone is tens of degrees off gravity, the gyro knows the attitude."""
    d = 1.0 / rate
    t = np.arange(int(14 * rate)) * d
    q_true = quat.from_rotvec([math.radians(20.0), 0.0, 0.0])
    f_world = np.stack([6.0 * np.sin(2 * np.pi * 1.5 * t), np.zeros_like(t), np.full_like(t, G)], 1)
    acc = quat.rotate(quat.conjugate(q_true), f_world)
    keep = ~((t > 10.0) & (t < 10.0 + hole))
    t = t[keep]
    dt = np.diff(np.concatenate([[t[0] - d], t]))
    return acc[keep], np.zeros((len(t), 3)), dt, t - (10.0 + hole), q_true


def swinging_stream(n: int, seed: int = 0, jitter: bool = True) -> tuple[list[tuple[float, ...]], list[float]]:
    """A swinging sensor: samples (acc, gyr) and steps (s), jittery or at 10 ms, with one 0.3 s hole."""
    rng = np.random.default_rng(seed)
    dt = rng.uniform(0.003, 0.012, n) if jitter else np.full(n, 0.010)
    dt[n // 2] = 0.3
    t = np.cumsum(dt)
    roll = 0.6 * np.sin(2.0 * np.pi * 0.8 * t)
    acc = np.column_stack([0.3 * np.sin(5 * t), G * np.sin(roll), G * np.cos(roll)]) + rng.normal(0, 0.05, (n, 3))
    gyr = np.column_stack([0.6 * 2 * np.pi * 0.8 * np.cos(2 * np.pi * 0.8 * t), 0.2 * np.sin(t), 0.1 + 0 * t])
    return [tuple(r) for r in np.column_stack([acc, gyr]).tolist()], dt.tolist()


def field_rows(n: int) -> list[tuple[float, float, float] | None]:
    return [None if k % 7 == 3 else (20e-6, 5e-6 * math.sin(k / 50), -40e-6) for k in range(n)]


def ramp_stream(rate: float, n: int = 400) -> tuple[list[tuple[float, ...]], list[float]]:
    """A regular stream: acc and gyr linear in time (gyr x = 0.5 + 0.1 t rad/s), ``n`` samples at ``rate``."""
    t = np.arange(n) / rate
    rows = np.column_stack([0 * t, 0 * t, G + 0 * t, 0.5 + 0.1 * t, 0 * t, 0 * t])
    return [tuple(r) for r in rows.tolist()], [1.0 / rate] * n


def outputs_of(stage: Any) -> list:
    """The records ``stage`` returns from now on, kept as the chain runs it (its ``run`` wrapped, nothing else)."""
    out: list = []
    run = stage.run

    def kept(block: Any) -> Any:
        out.append(run(block))
        return out[-1]

    stage.run = kept
    return out


def still_then_turning(n: int, seed: int = 3, rate: float = 200.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` noisy samples at ``rate``: level and still for the first half, then turning about all three axes
    (acc, gyr, dt)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / rate
    gyr = np.column_stack([np.sin(t), 0.5 * np.cos(2 * t), 0.3 * np.sin(0.5 * t)]) * (t > n / rate / 2)[:, None]
    gyr += rng.normal(0, 0.01, (n, 3))
    acc = np.array([0.0, 0.0, GRAVITY]) + rng.normal(0, 0.05, (n, 3))
    return acc, gyr, np.full(n, 1.0 / rate)
