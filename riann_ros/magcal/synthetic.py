"""Synthetic magnetometers with a known calibration, and a ground robot that turns about the vertical only
(ROS-free; for the tests and bench/magcal_study.py).

:func:`distort` makes the raw readings of a world field seen along a reference attitude:
``m_raw = D m_true + h + noise`` with ``D = S⁻¹`` (so the calibration that undoes it is ``m = S (m_raw − h)``).
:func:`ground_robot` is a robot on flat ground: its sensor, mounted with a fixed tilt, turns about the world
vertical only, in phases of rest, turns and straight driving (exact gyro, exact reference).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from riann_ros import quaternion as quat
from riann_ros.constants import GRAVITY
from riann_ros.recording import Recording

#: T; a mid-latitude geomagnetic field in magnetic ENU (y = magnetic north): 20 µT horizontal, dip 63°.
FIELD_ENU_T = (0.0, 20e-6, -40e-6)


def distort(quat_ref: ArrayLike, hard_iron_t: ArrayLike, soft_iron: ArrayLike | None = None,
            noise_t: float = 0.0, field_t: ArrayLike = FIELD_ENU_T, seed: int = 0) -> NDArray[np.float64]:
    """(N, 3) raw readings (T) of ``field_t`` (world, T) along ``quat_ref`` (sensor → world) through a sensor whose
    calibration is ``hard_iron_t`` and ``soft_iron`` (3×3 or 9 row-major ``S``; None: identity), with white noise of
    ``noise_t`` per axis."""
    q = np.asarray(quat_ref, dtype=float)
    true = quat.rotate(quat.conjugate(q), np.broadcast_to(np.asarray(field_t, dtype=float), (len(q), 3)))
    d = np.eye(3) if soft_iron is None else np.linalg.inv(np.asarray(soft_iron, dtype=float).reshape(3, 3))
    rng = np.random.default_rng(seed)
    return true @ d.T + np.asarray(hard_iron_t, dtype=float) + noise_t * rng.normal(size=(len(q), 3))


def ground_robot(phases: list[tuple[str, float, float]], rate_hz: float = 100.0, mount_rpy_deg: ArrayLike = (0, 0, 0),
                 gyr_noise: float = 0.0, seed: int = 0) -> Recording:
    """A sensor turning about the world vertical only. ``phases``: ``(kind, seconds, yaw rate °/s)`` with kind
    ``rest``, ``turn`` (the rate, with raised-cosine ramps of 0.5 s at both ends) or ``straight`` (no rotation);
    ``mount_rpy_deg`` the sensor's fixed roll, pitch, yaw on the robot."""
    dt = 1.0 / rate_hz
    rates = []
    for kind, secs, dps in phases:
        n = max(round(secs * rate_hz), 1)
        if kind != "turn":
            rates.append(np.zeros(n))
            continue
        t = np.arange(n) * dt
        ramp = np.clip(np.minimum(t, secs - t) / 0.5, 0.0, 1.0)
        rates.append(np.radians(dps) * 0.5 * (1.0 - np.cos(np.pi * ramp)))
    yaw_rate = np.concatenate(rates)
    n = len(yaw_rate)
    yaw = np.concatenate([[0.0], np.cumsum(0.5 * (yaw_rate[1:] + yaw_rate[:-1]) * dt)])
    r, p, y = np.radians(np.asarray(mount_rpy_deg, dtype=float))
    mount = quat.multiply(quat.multiply(_axis(2, y), _axis(1, p)), _axis(0, r))
    q = quat.multiply(np.column_stack([np.cos(0.5 * yaw), np.zeros(n), np.zeros(n), np.sin(0.5 * yaw)]), mount)
    w_body = quat.rotate(quat.conjugate(mount), np.column_stack([np.zeros(n), np.zeros(n), yaw_rate]))
    rng = np.random.default_rng(seed)
    gyr = w_body + gyr_noise * rng.normal(size=(n, 3))
    acc = quat.rotate(quat.conjugate(q), np.broadcast_to(np.array([0.0, 0.0, GRAVITY]), (n, 3)))
    stamps = np.round(np.arange(n) * dt * 1e9).astype(np.int64)
    return Recording(stamps_ns=stamps, acc=acc, gyr=gyr, quat_ref=q, name="ground_robot", dataset="synthetic",
                     source="riann_ros.magcal.synthetic")


def _axis(i: int, angle: float) -> NDArray[np.float64]:
    q = np.zeros(4)
    q[0] = np.cos(0.5 * angle)
    q[1 + i] = np.sin(0.5 * angle)
    return q
