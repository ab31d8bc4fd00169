"""Sensors with a magnetometer field, shared by the 9D tests (test_mag, test_9d_smoke, test_riann_s7*)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers_riann import G

from riann_ros import quaternion as quat
from riann_ros.datasets.synthetic import generate
from riann_ros.estimators import estimator_class
from riann_ros.recording import Recording
from riann_ros.stream import EstimatorStream

#: the geomagnetic field in magnetic ENU (tesla): y = magnetic north, a downward vertical part (dip ≈ 63°)
FIELD_ENU = np.array([0.0, 20e-6, -40e-6])


ESTIMATORS = ("riann", "vqf", "madgwick", "mahony")


#: process == process_batch tolerance (RIANN: float32 network, batch and single-row calls round differently)
STREAM_TOL = {"riann": 1e-5}


NAN3 = np.full(3, np.nan)


IDENTITY_Q = (1.0, 0.0, 0.0, 0.0)


def rot_z(angle: float) -> np.ndarray:
    return np.array([math.cos(0.5 * angle), 0.0, 0.0, math.sin(0.5 * angle)])


def sign_aligned(ref: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``q`` with each row's sign chosen to match ``ref`` (q and −q are the same attitude)."""
    return q * np.where(np.sum(ref * q, axis=-1, keepdims=True) < 0.0, -1.0, 1.0)


def gravity_angle(q1: np.ndarray, q2: np.ndarray) -> np.ndarray:
    """Angle (rad) between the world vertical seen in the sensor frame, R(q)ᵀ e_z, of two estimates."""
    g1 = quat.rotate(quat.conjugate(q1), np.array([0.0, 0.0, 1.0]))
    g2 = quat.rotate(quat.conjugate(q2), np.array([0.0, 0.0, 1.0]))
    return np.arctan2(np.linalg.norm(np.cross(g1, g2), axis=-1), np.sum(g1 * g2, axis=-1))


def heading_change_deg(q_from: np.ndarray, q: np.ndarray) -> np.ndarray:
    return np.degrees(quat.heading_error(q_from, q))


def field_of(q_true: np.ndarray, noise: float = 0.0, seed: int = 0) -> np.ndarray:
    """m_sensor = R(q)ᵀ m_world (+ white noise, T)."""
    m = quat.rotate(quat.conjugate(q_true), FIELD_ENU)
    if noise:
        m = m + noise * np.random.default_rng(seed).standard_normal(m.shape)
    return m


def moving(duration: float = 12.0, rate: float = 100.0, seed: int = 3, mag_noise: float = 0.2e-6, **kw) -> Recording:
    """The synthetic generator's rotation motion (rest first) with the field of :data:`FIELD_ENU`."""
    rec = generate(rate=rate, duration=duration, seed=seed, motion="rotation", start_s=1.0, **kw)
    assert rec.quat_ref is not None
    rec.mag = field_of(rec.quat_ref, mag_noise, seed)
    return rec


def static(q_true: np.ndarray, n: int, rate: float = 100.0, seed: int = 0) -> Recording:
    """A sensor at rest in attitude ``q_true`` with sensor noise and the field of :data:`FIELD_ENU`."""
    rng = np.random.default_rng(seed)
    acc = quat.rotate(quat.conjugate(q_true), np.array([0.0, 0.0, G])) + 0.03 * rng.standard_normal((n, 3))
    gyr = 0.004 * rng.standard_normal((n, 3))
    mag = field_of(q_true) + 0.2e-6 * rng.standard_normal((n, 3))
    stamps = 10**9 + np.round(np.arange(n) * 1e9 / rate).astype(np.int64)
    return Recording(stamps, acc, gyr, np.tile(q_true, (n, 1)), name="static", dataset="synth", mag=mag)


def skip_without_mag(name: str) -> None:
    if not estimator_class(name).USES_MAG:
        pytest.skip(f"{name} has no magnetometer support (USES_MAG is False)")


def per_sample(stream: EstimatorStream, stamps, acc, gyr, mag) -> tuple[np.ndarray, np.ndarray]:
    """:meth:`EstimatorStream.process` over a sequence, NaN rows where rejected; a NaN row of ``mag`` (the evaluator's
    "no reading") is given as None, as the node's pairing gives it."""
    out = np.full((len(stamps), 4), np.nan)
    ok = np.zeros(len(stamps), dtype=bool)
    for i in range(len(stamps)):
        m = None if mag is None or np.isnan(mag[i]).all() else mag[i]
        q, r = stream.process(int(stamps[i]), acc[i], gyr[i], mag=m)
        if q is not None:
            out[i], ok[i] = q, r.accepted
    return out, ok


def delayed_field(rec: Recording, delay_samples: int) -> np.ndarray:
    """The field of :data:`FIELD_ENU` read ``delay_samples`` samples late (the first readings repeat)."""
    assert rec.quat_ref is not None
    q_late = np.vstack([np.repeat(rec.quat_ref[:1], delay_samples, axis=0), rec.quat_ref[: len(rec) - delay_samples]])
    return field_of(q_late, 0.2e-6, seed=5)
