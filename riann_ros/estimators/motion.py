"""What a recording's gyro and accelerometer say of its motion, for the offline magnetometer calibration (ROS-free).

:func:`gyro_motion` is the input of :func:`riann_ros.magcal.bag_fit.calibrate_recording`: the gyro with its bias
removed the way the estimators remove it (:class:`~.bias.GyroBiasFrontEnd`: VQF's rest and motion bias estimate,
causal), and VQF's 6D attitude (tilt from the accelerometer, heading from the integrated gyro, no magnetometer), in
which a world-fixed field seen through a correct calibration keeps its direction.
"""

from __future__ import annotations

from riann_ros.estimators.bias import GyroBiasFrontEnd
from riann_ros.estimators.vqf_estimator import VqfEstimator
from riann_ros.magcal.bag_fit import GyroMotion
from riann_ros.recording import Recording


def gyro_motion(rec: Recording) -> GyroMotion:
    """The bias-corrected gyro and the 6D attitude of ``rec`` (module docstring)."""
    dt = rec.dt
    gyr = rec.gyr - GyroBiasFrontEnd(float(dt[0])).update_batch(rec.acc, rec.gyr, dt)
    return GyroMotion(gyr=gyr, attitude=VqfEstimator().update_batch(rec.acc, rec.gyr, dt))
