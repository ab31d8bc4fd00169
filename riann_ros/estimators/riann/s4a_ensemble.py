"""Stage 4a, the ensemble: RIANN run on rotated copies of the IMU frame, gravity directions averaged (ROS-free).

RIANN was trained with virtual IMU rotations, so a copy fed the IMU in another frame gives an estimate whose
error is partly independent. Copy 0 is the sensor frame; the others see it turned by 180° about three orthogonal
axes in general position (:func:`frames`). Copy ``m`` sees ``R_m acc``, ``R_m gyr``; its gravity direction maps
back by ``R_mᵀ``; the ensemble attitude is copy 0's tilted to the normalised mean direction, and how far the copies'
directions spread around their mean is one input of the uncertainty the estimator reports (stage 8; it never
changes the attitude). :func:`combine` is the reference, vectorised over rows; :func:`combine_floats` does the same
for the few rows of a node's call in plain floats (numpy's per-call overhead is most of the cost there), and is
tested against it on random inputs. Physics and measurements: docs/riann.md, stage 4.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from riann_ros import quaternion as quat
from riann_ros.rotations import gravity, tilt_to

Array = NDArray[np.float64]

MAX_COPIES = 4


def _axes() -> Array:
    """Three orthonormal axes in general position: the columns of the rotation by 1 rad about (1, 2, 3)/√14
    (each at least 33° from every sensor axis)."""
    k = np.array([1.0, 2.0, 3.0]) / np.sqrt(14.0)
    c, s = np.cos(1.0), np.sin(1.0)
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) * c + s * kx + (1.0 - c) * np.outer(k, k)  # columns: the axes


def frames(n: int) -> list[Array]:
    """The rotation matrices of ``n`` copies (1 ≤ n ≤ :data:`MAX_COPIES`): the identity, then 180° turns
    about the three axes of :func:`_axes` (R = 2 a aᵀ − I)."""
    if not 1 <= n <= MAX_COPIES:
        raise ValueError(f"ensemble must be 1 to {MAX_COPIES}, got {n}")
    ax = _axes()
    return [np.eye(3)] + [2.0 * np.outer(ax[:, i], ax[:, i]) - np.eye(3) for i in range(n - 1)]


def rotate_rows(rows: Array, r: Array) -> Array:
    """Network input rows (M, 7: acc, gyr, dt) in the frame turned by ``r``."""
    out = rows.copy()
    out[:, 0:3] = rows[:, 0:3] @ r.T
    out[:, 3:6] = rows[:, 3:6] @ r.T
    return out


def copy_rows(rots: list[Array]) -> Callable[[Array], NDArray[np.float32]]:
    """A function giving every copy's network rows (copies, M, 7) float32 from rows (M, 7): one matmul with the
    block-diagonal ``(R, R, 1)`` of each copy (copy 0 the rows themselves; the zero terms change no value)."""
    r7 = np.zeros((len(rots), 7, 7))
    for m, r in enumerate(rots):
        r7[m, :3, :3] = r
        r7[m, 3:6, 3:6] = r
        r7[m, 6, 6] = 1.0
    r7t = np.ascontiguousarray(r7.transpose(0, 2, 1))
    return lambda x: (x[None] @ r7t).astype(np.float32)


def gravity_rows(q: Array) -> Array:
    """World z (up) in the sensor frame, R(q)ᵀ e_z, of attitudes (M, 4) w, x, y, z."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.column_stack([2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)])


def combine(units: list[Array], rots: list[Array]) -> tuple[Array, Array]:
    """The ensemble attitude (M, 4) from the copies' unit-quaternion outputs ``units[m]`` (M, 4) in their frames
    ``rots[m]``: copy 0's attitude tilted to the mean gravity direction; and per row how far the copies' gravity
    directions spread around their mean (rad): ``√(2 (1 − R))`` with ``R`` the length of the mean of the ``n`` unit
    directions, for small angles the root mean square of their angles from the mean direction (0 for one copy)."""
    q0 = units[0]
    n = len(units)
    if n == 1:
        return q0, np.zeros(len(q0))
    u = gravity_rows(q0)
    v = u.copy()
    for q, r in zip(units[1:], rots[1:], strict=True):
        v += gravity_rows(q) @ r  # row form of Rᵀ g'
    length = np.linalg.norm(v, axis=1, keepdims=True)
    v /= length
    spread = np.sqrt(np.maximum(2.0 * (1.0 - length[:, 0] / n), 0.0))
    ax = np.cross(u, v)
    s = np.linalg.norm(ax, axis=1)
    a = np.arctan2(s, np.sum(u * v, axis=1))
    h = np.where(s > 1e-12, -np.sin(0.5 * a) / np.maximum(s, 1e-300), 0.0)
    r_inv = np.column_stack([np.cos(0.5 * a), ax * h[:, None]])  # the turn taking u to v, inverted
    return quat.normalize(quat.multiply(q0, r_inv)), spread


def combine_floats(outs: list[Array], rots: list[Array]) -> tuple[Array, Array]:
    """:func:`combine` of a few rows of two or more copies in plain floats, the copies' outputs normalised first."""
    rl = [r.tolist() for r in rots]
    rows = [_combine_row([o[i].tolist() for o in outs], rl) for i in range(len(outs[0]))]
    return np.array([r[0] for r in rows]), np.array([r[1] for r in rows])


def _combine_row(qs: list[list[float]], rots: list[list[list[float]]]) -> tuple[list[float], float]:
    """:func:`combine` of one row in plain floats (the copies' outputs normalised first)."""
    units: list[tuple[float, float, float, float]] = []
    for q in qs:
        n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
        units.append((q[0] / n, q[1] / n, q[2] / n, q[3] / n))
    vx, vy, vz = gravity(units[0])
    for u, r in zip(units[1:], rots[1:], strict=True):
        gx, gy, gz = gravity(u)
        vx += gx * r[0][0] + gy * r[1][0] + gz * r[2][0]  # Rᵀ g
        vy += gx * r[0][1] + gy * r[1][1] + gz * r[2][1]
        vz += gx * r[0][2] + gy * r[1][2] + gz * r[2][2]
    length = math.sqrt(vx * vx + vy * vy + vz * vz)
    w, x, y, z = tilt_to(units[0], (vx / length, vy / length, vz / length))
    n = math.sqrt(w * w + x * x + y * y + z * z)
    return [w / n, x / n, y / n, z / n], math.sqrt(max(2.0 * (1.0 - length / len(qs)), 0.0))
