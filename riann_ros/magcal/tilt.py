"""The calibration's own tilt: an attitude the gyro carries and the accelerometer pulls toward gravity (ROS-free).

The online calibration needs the sensor's tilt (the windows' tolerance, the heading σ at the current tilt); its
heading does not matter. Where the estimator does not give its own attitude (Madgwick, Mahony, VQF: their attitude
depends on the calibrated field, which would tie the calibration to the filter it feeds), the front end keeps this
one (:class:`~riann_ros.magcal.frontend.MagFrontEnd`): the gyro carries it and the accelerometer pulls it toward
gravity with the time constant :data:`TILT_TAU_S` (VQF's ``tauAcc`` default), so a linear acceleration or a tap does
not tilt it; the first accelerometer sample sets it.
"""

from __future__ import annotations

import math

from riann_ros.rotations import Quat, from_rotvec, normalized, qmul, rotate

#: s; the time constant with which the calibration's attitude follows the accelerometer (VQF's tauAcc default)
TILT_TAU_S = 3.0


class TiltFilter:
    """The calibration's attitude (module docstring); :attr:`q` is its whole state (None before the first
    accelerometer sample with a direction)."""

    def __init__(self) -> None:
        self.q: Quat | None = None

    def step(self, delta: Quat, dt: float, ax: float, ay: float, az: float) -> Quat | None:
        """The attitude after a sample: ``delta`` its gyro increment, ``dt`` its step (s), ``(ax, ay, az)`` its
        accelerometer (any unit)."""
        n = math.sqrt(ax * ax + ay * ay + az * az)
        if self.q is None:
            self.q = accelerometer_tilt(ax, ay, az)
            return self.q
        q = normalized(qmul(self.q, delta))
        if 0.0 < n < math.inf:
            ux, uy, uz = rotate(q, (ax / n, ay / n, az / n))  # the measured "up" in the world frame
            k = min(dt / TILT_TAU_S, 1.0)  # rotate it toward +z by this share of the angle between them
            c = max(-1.0, min(1.0, uz))
            s = math.sqrt(ux * ux + uy * uy)
            if s > 0.0:
                angle = k * math.atan2(s, c)
                q = normalized(qmul(from_rotvec(uy / s * angle, -ux / s * angle, 0.0), q))
        self.q = q
        return q


def accelerometer_tilt(ax: float, ay: float, az: float) -> Quat | None:
    """The zero-heading attitude of an accelerometer sample (the shortest rotation of its direction onto +z), or
    None without one: the calibration needs only the tilt."""
    n = math.sqrt(ax * ax + ay * ay + az * az)
    if not 0.0 < n < math.inf:
        return None
    w = 1.0 + az / n
    if w < 1e-9:  # upside down: half a turn about x
        return (0.0, 1.0, 0.0, 0.0)
    k = 1.0 / math.sqrt(w * w + (ay / n) ** 2 + (ax / n) ** 2)
    return (w * k, ay / n * k, -ax / n * k, 0.0)
