"""Helpers shared by the classical filters (Madgwick, Mahony, VQF), ROS-free.

Input sanitising (the documented degenerate-input rules), the accelerometer initialisation of
Madgwick and Mahony (and, with a magnetometer, the heading from the field), and list ↔ array conversion
for their plain-float loops.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from riann_ros import quaternion as quat
from riann_ros.estimators.base import Array
from riann_ros.rotations import Quat

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


def sanitize_mag(mag: ArrayLike, n: int) -> list:
    """The magnetic field as an ``(N, 3)`` nested list of Python floats; non-finite rows → zeros.

    A zero row means "no field for this sample" (the loops then run their 6D step), so a NaN row and an
    all-zero row are handled alike.
    """
    m = np.array(mag, dtype=float, copy=True).reshape(-1, 3)
    if m.shape != (n, 3):
        raise ValueError(f"mag must have one row per sample, got {m.shape} for {n} samples")
    m[~np.isfinite(m).all(axis=1)] = 0.0
    return m.tolist()


def has_field(mx: float, my: float, mz: float) -> bool:
    """True when a (sanitised) magnetometer sample carries a direction: non-zero and of finite norm."""
    return 0.0 < mx * mx + my * my + mz * mz < math.inf


def initial_attitude_marg(ax: float, ay: float, az: float, mx: float, my: float, mz: float) -> Quat | None:
    """Sensor → ENU attitude from one accelerometer and one magnetometer sample, or None (no usable acc).

    The zero-heading attitude of :func:`initial_attitude`, then a rotation about world z that puts the
    horizontal part of the tilt-compensated field ``R(q) m`` on +y (magnetic north). Without a field (zero,
    non-finite, or vertical) the heading stays zero, as in :func:`initial_attitude`.
    """
    q = initial_attitude(ax, ay, az)
    if q is None or not has_field(mx, my, mz):
        return q
    w, x, y, z = q
    # m_w = R(q) m = m + w t + q_vec × t with t = 2 q_vec × m (only its horizontal part is needed)
    tx = 2.0 * (y * mz - z * my)
    ty = 2.0 * (z * mx - x * mz)
    tz = 2.0 * (x * my - y * mx)
    hx = mx + w * tx + (y * tz - z * ty)
    hy = my + w * ty + (z * tx - x * tz)
    if not (0.0 < hx * hx + hy * hy < math.inf):
        return q
    psi = math.atan2(hx, hy)  # angle of the horizontal field from +y toward +x
    c = math.cos(0.5 * psi)
    s = math.sin(0.5 * psi)
    # rot_z(psi) ⊗ q
    rw, rx, ry, rz = c * w - s * z, c * x - s * y, c * y + s * x, c * z + s * w
    n = math.sqrt(rw * rw + rx * rx + ry * ry + rz * rz)
    return rw / n, rx / n, ry / n, rz / n


def initialise_marg(q: Quat | None, acc: list, mag: list, out: list) -> tuple[Quat | None, int, bool]:
    """:func:`initialise` with the heading from the field of the initialising sample, if it has one.

    Returns the attitude (None when no sample was usable), the index of the first sample to filter, and
    whether this call set the attitude from a sample with a field (its heading then comes from the field).
    """
    i = 0
    while q is None and i < len(acc):
        q = initial_attitude_marg(*acc[i], *mag[i])
        out.append(q if q is not None else (1.0, 0.0, 0.0, 0.0))
        i += 1
    return q, i, i > 0 and q is not None and has_field(*mag[i - 1])


def as_array(rows: list) -> Array:
    """(N, 4) array from a list of 4-tuples (also for N = 0)."""
    return np.array(rows, dtype=float).reshape(-1, 4)
