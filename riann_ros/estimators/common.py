"""Helpers shared by the classical filters (Madgwick, Mahony, VQF), ROS-free.

Input sanitising (the documented degenerate-input rules), the accelerometer initialisation of
Madgwick and Mahony, and list ↔ array conversion for their plain-float loops.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from riann_ros import quaternion as quat
from riann_ros.estimators.base import Array

Quat = tuple[float, float, float, float]
BIAS_KEY = "gyro bias estimate (deg/s)"


def bias_text(bias_rad_s: ArrayLike) -> str:
    """A gyro-bias estimate (rad/s) as diagnostics text in °/s."""
    return ", ".join(f"{v:.3f}" for v in np.degrees(np.asarray(bias_rad_s, dtype=float)))


def sanitize_arrays(acc: ArrayLike, gyr: ArrayLike, dt: ArrayLike) -> tuple[Array, Array, Array]:
    """Copies of the inputs as ``(N, 3), (N, 3), (N,)`` float arrays, degenerate values neutralised.

    Non-finite acc rows → zeros (gyro-only step), non-finite gyr rows → zeros, non-finite or negative
    dt → 0. ``dt`` may be a scalar (broadcast).
    """
    acc = np.array(acc, dtype=float, copy=True).reshape(-1, 3)
    gyr = np.array(gyr, dtype=float, copy=True).reshape(-1, 3)
    n = len(acc)
    if gyr.shape != (n, 3):
        raise ValueError(f"acc and gyr must have the same number of samples, got {acc.shape} and {gyr.shape}")
    dt = np.array(np.broadcast_to(np.asarray(dt, dtype=float), (n,)), dtype=float)
    acc[~np.isfinite(acc).all(axis=1)] = 0.0
    gyr[~np.isfinite(gyr).all(axis=1)] = 0.0
    dt[~(np.isfinite(dt) & (dt > 0.0))] = 0.0
    return acc, gyr, dt


def sanitize(acc: ArrayLike, gyr: ArrayLike, dt: ArrayLike) -> tuple[list, list, list]:
    """:func:`sanitize_arrays` as nested lists of Python floats, for the per-sample loops."""
    a, g, h = sanitize_arrays(acc, gyr, dt)
    return a.tolist(), g.tolist(), h.tolist()


def initialise(q: Quat | None, acc: list, out: list
               ) -> tuple[Quat | None, int]:
    """Until the first usable accelerometer sample sets the attitude, output the identity.

    Returns the attitude (None when no sample was usable) and the index of the first sample to
    filter; the outputs of the samples consumed are appended to ``out``.
    """
    i = 0
    while q is None and i < len(acc):
        q = initial_attitude(*acc[i])
        out.append(q if q is not None else (1.0, 0.0, 0.0, 0.0))
        i += 1
    return q, i


def initial_attitude(ax: float, ay: float, az: float) -> Quat | None:
    """Zero-heading attitude from one accelerometer sample, or None when it carries no direction."""
    if not (ax * ax + ay * ay + az * az > 0.0):
        return None
    w, x, y, z = quat.from_accelerometer([ax, ay, az]).tolist()
    return w, x, y, z


def as_array(rows: list) -> Array:
    """(N, 4) array from a list of 4-tuples (also for N = 0)."""
    return np.array(rows, dtype=float).reshape(-1, 4)
