"""Rotations in plain Python floats, ROS-free: the per-sample hot paths' twin of :mod:`riann_ros.quaternion`.

A node processes one sample per message, where numpy's per-call overhead costs more than the arithmetic; these
helpers do the same math on tuples. Conventions as in :mod:`riann_ros.quaternion`: unit quaternions
``(w, x, y, z)``, sensor → world (z up), ``v_world = q ⊗ v ⊗ q⁻¹``. Angles in radians (one degree:
:data:`riann_ros.constants.DEG`).
"""

from __future__ import annotations

import math

Quat = tuple[float, float, float, float]
Vec = tuple[float, float, float]

IDENTITY: Quat = (1.0, 0.0, 0.0, 0.0)


def qmul(p: Quat, q: Quat) -> Quat:
    """Hamilton product ``p ⊗ q``."""
    pw, px, py, pz = p
    qw, qx, qy, qz = q
    return (pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw)


def conj(q: Quat) -> Quat:
    """The conjugate (inverse of a unit quaternion)."""
    return (q[0], -q[1], -q[2], -q[3])


def normalized(q: Quat) -> Quat:
    """``q`` scaled to unit norm."""
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


def rotate(q: Quat, v: Vec) -> Vec:
    """``R(q) v`` for a unit quaternion ``q``."""
    w, x, y, z = q
    vx, vy, vz = v
    tx = 2.0 * (y * vz - z * vy)
    ty = 2.0 * (z * vx - x * vz)
    tz = 2.0 * (x * vy - y * vx)
    return (vx + w * tx + (y * tz - z * ty), vy + w * ty + (z * tx - x * tz), vz + w * tz + (x * ty - y * tx))


def cross(a: Vec, b: Vec) -> Vec:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def unit(v: Vec) -> Vec:
    n = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    return (v[0] / n, v[1] / n, v[2] / n)


def from_rotvec(x: float, y: float, z: float) -> Quat:
    """The unit quaternion of the rotation vector ``(x, y, z)`` (axis × angle)."""
    a = math.sqrt(x * x + y * y + z * z)
    if a < 1e-12:
        return (1.0, 0.5 * x, 0.5 * y, 0.5 * z)
    k = math.sin(0.5 * a) / a
    return (math.cos(0.5 * a), x * k, y * k, z * k)


def to_rotvec(q: Quat) -> Vec:
    """The rotation vector of a unit quaternion (small angles fine)."""
    w, x, y, z = q
    s = math.sqrt(x * x + y * y + z * z)
    if s < 1e-12:
        return (2.0 * x, 2.0 * y, 2.0 * z)
    a = 2.0 * math.atan2(s, w) / s
    return (a * x, a * y, a * z)


def about_z(angle: float) -> Quat:
    """The rotation by ``angle`` about world z (the vertical)."""
    h = 0.5 * angle
    return (math.cos(h), 0.0, 0.0, math.sin(h))


def twist(q: Quat) -> float:
    """Angle (rad, in (-π, π]) of the rotation about z in the swing-twist split of ``q``."""
    return math.remainder(2.0 * math.atan2(q[3], q[0]), 2.0 * math.pi)


def gravity(q: Quat) -> Vec:
    """World z (up) in the sensor frame of the sensor-to-world attitude ``q``: ``R(q)ᵀ e_z``."""
    w, x, y, z = q
    return (2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y))


def toward(a: Vec, b: Vec, k: float) -> Vec:
    """Unit vector ``a`` turned toward unit vector ``b`` by the fraction ``k`` of the angle between them."""
    c = max(-1.0, min(1.0, a[0] * b[0] + a[1] * b[1] + a[2] * b[2]))
    th = math.acos(c)
    s = math.sin(th)
    if s < 1e-9:  # the same direction, or opposite (no unique path): b
        return b
    fa, fb = math.sin((1.0 - k) * th) / s, math.sin(k * th) / s
    return unit((fa * a[0] + fb * b[0], fa * a[1] + fb * b[1], fa * a[2] + fb * b[2]))


def tilt_to(q: Quat, v: Vec) -> Quat:
    """``q`` turned by the smallest rotation that makes its gravity direction :func:`gravity` equal ``v`` (about a
    horizontal axis: the heading of ``q`` is kept)."""
    u = gravity(q)
    ax = cross(u, v)
    s = math.sqrt(ax[0] * ax[0] + ax[1] * ax[1] + ax[2] * ax[2])
    if s < 1e-12:
        return q
    a = math.atan2(s, u[0] * v[0] + u[1] * v[1] + u[2] * v[2])
    h = -math.sin(0.5 * a) / s
    return qmul(q, (math.cos(0.5 * a), ax[0] * h, ax[1] * h, ax[2] * h))  # q ⊗ r⁻¹, r takes u to v (sensor frame)
