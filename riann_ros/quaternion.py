"""Quaternion math, ROS-free and vectorised.

Convention throughout the project: unit quaternions as numpy arrays ``[w, x, y, z]`` (scalar first),
shape ``(4,)`` or ``(N, 4)``, describing the orientation of the sensor frame with respect to a world
frame whose z axis points up (ENU, REP-103): ``v_world = q ⊗ v_sensor ⊗ q⁻¹``. ROS messages store
``x, y, z, w``: the ROS layer and the bag codec read and write the fields by name.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]

IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])


def multiply(p: ArrayLike, q: ArrayLike) -> Array:
    """Hamilton product ``p ⊗ q`` (broadcasting over leading axes)."""
    p = np.asarray(p, dtype=float)
    q = np.asarray(q, dtype=float)
    pw, px, py, pz = np.moveaxis(p, -1, 0)
    qw, qx, qy, qz = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ],
        axis=-1,
    )


def conjugate(q: ArrayLike) -> Array:
    """Conjugate (the inverse of a unit quaternion)."""
    q = np.array(q, dtype=float)
    q[..., 1:] *= -1.0
    return q


def normalize(q: ArrayLike) -> Array:
    """Scale to unit norm along the last axis."""
    q = np.asarray(q, dtype=float)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def from_rotvec(v: ArrayLike) -> Array:
    """Quaternion of the rotation vector ``v`` (axis × angle, rad)."""
    v = np.asarray(v, dtype=float)
    angle = np.linalg.norm(v, axis=-1, keepdims=True)
    half = 0.5 * angle
    # sin(half)/angle with a series expansion near zero
    with np.errstate(invalid="ignore", divide="ignore"):
        k = np.where(angle > 1e-8, np.sin(half) / np.where(angle > 0, angle, 1.0), 0.5 - angle**2 / 48.0)
    return np.concatenate([np.cos(half), v * k], axis=-1)


def rotate(q: ArrayLike, v: ArrayLike) -> Array:
    """Rotate vector(s) ``v`` by ``q``: ``q ⊗ [0, v] ⊗ q⁻¹``."""
    v = np.asarray(v, dtype=float)
    qv = np.concatenate([np.zeros((*v.shape[:-1], 1)), v], axis=-1)
    return multiply(multiply(q, qv), conjugate(q))[..., 1:]


def from_accelerometer(acc: ArrayLike) -> Array:
    """Attitude (zero heading) that maps the measured specific force ``acc`` onto world +z.

    At rest an accelerometer measures the reaction to gravity, pointing up in the world. The
    returned quaternion is the shortest rotation taking the normalised ``acc`` (sensor frame) to
    ``[0, 0, 1]`` (world frame). For ``acc`` pointing straight down it returns a 180° rotation about x.
    """
    a = np.asarray(acc, dtype=float)
    a = a / np.linalg.norm(a)
    ez = np.array([0.0, 0.0, 1.0])
    w = 1.0 + float(np.dot(a, ez))
    if w < 1e-9:
        return np.array([0.0, 1.0, 0.0, 0.0])
    axis = np.cross(a, ez)
    return normalize(np.array([w, axis[0], axis[1], axis[2]]))


def slerp(q0: ArrayLike, q1: ArrayLike, s: ArrayLike) -> Array:
    """Spherical linear interpolation between unit quaternions, ``s`` in [0, 1] (broadcasting)."""
    q0 = np.asarray(q0, dtype=float)
    q1 = np.asarray(q1, dtype=float)
    s = np.asarray(s, dtype=float)[..., None]
    dot = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(dot < 0.0, -q1, q1)  # shortest path
    dot = np.clip(np.abs(dot), -1.0, 1.0)
    theta = np.arccos(dot)
    sin_t = np.sin(theta)
    small = sin_t < 1e-9
    safe = np.where(small, 1.0, sin_t)
    a = np.where(small, 1.0 - s, np.sin((1.0 - s) * theta) / safe)
    b = np.where(small, s, np.sin(s * theta) / safe)
    return normalize(a * q0 + b * q1)


def inclination_error(q_true: ArrayLike, q_est: ArrayLike) -> Array:
    """Attitude (inclination) error e_α in radians, paper eq. 3, heading ignored.

    ``q_err = q_true ⊗ q_est⁻¹`` (world frame), ``e_α = 2·arccos(√(w² + z²))``. Sign-invariant in
    both arguments. Rows with NaN give NaN.
    """
    qe = multiply(q_true, conjugate(q_est))
    qe = qe / np.linalg.norm(qe, axis=-1, keepdims=True)
    c = np.sqrt(qe[..., 0] ** 2 + qe[..., 3] ** 2)
    return 2.0 * np.arccos(np.clip(c, -1.0, 1.0))


def heading_error(q_true: ArrayLike, q_est: ArrayLike) -> Array:
    """Heading error in radians: the angle of the rotation about world z left after removing e_α."""
    qe = multiply(q_true, conjugate(q_est))
    qe = qe / np.linalg.norm(qe, axis=-1, keepdims=True)
    return np.abs((2.0 * np.arctan2(qe[..., 3], qe[..., 0]) + np.pi) % (2.0 * np.pi) - np.pi)


def total_error(q_true: ArrayLike, q_est: ArrayLike) -> Array:
    """Total rotation angle between the two orientations in radians."""
    qe = multiply(q_true, conjugate(q_est))
    qe = qe / np.linalg.norm(qe, axis=-1, keepdims=True)
    return 2.0 * np.arccos(np.clip(np.abs(qe[..., 0]), -1.0, 1.0))
