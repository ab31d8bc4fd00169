"""Stage 7b, the magnetometer's latency: estimated online from the field's rotation against the gyro's (ROS-free).

The estimator lives in :mod:`riann_ros.magcal.latency` (the classical filters' calibration front end uses it too).
docs/riann.md, stage 7 (the heading), and docs/magnetometer.md.
"""

from __future__ import annotations

from riann_ros.magcal.latency import DELAY_PRIOR, DELAY_TAU, MAX_DELAY, MAX_WINDOW, WINDOW, LatencyEstimator

__all__ = ["DELAY_PRIOR", "DELAY_TAU", "MAX_DELAY", "MAX_WINDOW", "WINDOW", "LatencyEstimator"]
