"""The field heading: the one kernel every part of the magnetometer wing and every estimator computes a heading from a
field with (ROS-free).

The heading of a field is the angle of its horizontal part in the world frame (ENU, z up) from +y (magnetic north)
toward +x: ``atan2(w_x, w_y)`` for the world-frame field ``w = R(q) m``, ``q`` the attitude (sensor → world) and
``m`` the field in the sensor frame. It is zero when the horizontal field points along +y, and it is not defined
for a vertical field (no horizontal part).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from riann_ros.rotations import Quat, Vec, rotate


def heading_angle(wx: float, wy: float) -> float:
    """rad; the heading of a world-frame horizontal direction ``(wx, wy)``: its angle from +y toward +x."""
    return math.atan2(wx, wy)


def heading_angles(w: NDArray[np.float64]) -> NDArray[np.float64]:
    """rad; :func:`heading_angle` of world-frame fields ``w`` (N, 3), vectorised."""
    return np.arctan2(w[:, 0], w[:, 1])


def field_heading(q: Quat, m: Vec) -> float | None:
    """rad; the heading of the tilt-compensated field ``R(q) m`` (``q`` sensor → ENU, ``m`` sensor frame); None when
    its horizontal part is zero or not finite."""
    hx, hy, _ = rotate(q, m)
    return heading_angle(hx, hy) if 0.0 < hx * hx + hy * hy < math.inf else None


def calibrated_world(a: tuple[float, ...], c: tuple[float, ...], m: Vec, q: Quat) -> Vec:
    """The raw reading ``m`` (µT) calibrated with ``(a, c)`` (row-major soft iron, ``c`` in µT) and rotated into the
    world frame by the attitude ``q`` (sensor → world), µT."""
    x, y, z = m
    return rotate(q, (a[0] * x + a[1] * y + a[2] * z - c[0], a[3] * x + a[4] * y + a[5] * z - c[1],
                      a[6] * x + a[7] * y + a[8] * z - c[2]))


def heading_of(a: tuple[float, ...], c: tuple[float, ...], m: Vec, q: Quat) -> float:
    """rad; the heading of the raw reading ``m`` calibrated with ``(a, c)`` at the attitude ``q``
    (:func:`calibrated_world`)."""
    w = calibrated_world(a, c, m, q)
    return heading_angle(w[0], w[1])


def heading_gap(a: tuple[float, ...], c: tuple[float, ...], m: Vec, q: Quat, field_world_t: Vec) -> float:
    """rad; the heading difference between the raw reading ``m`` calibrated with ``(a, c)`` at the attitude ``q``
    (:func:`calibrated_world`) and ``field_world_t`` (another calibration's, world frame): the angle between their
    horizontal parts."""
    w = calibrated_world(a, c, m, q)
    f = field_world_t
    return abs(math.atan2(w[0] * f[1] - w[1] * f[0], w[0] * f[0] + w[1] * f[1]))
