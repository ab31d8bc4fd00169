"""The evaluator's magnetometer pairing (ROS-free): a bag's ``/imu/mag`` readings are paired with the IMU samples
the way the nodes pair them (:mod:`riann_ros.magcal.input`: the newest reading stamped at or before the sample, at most
``mag_timeout`` older, never waiting), chunk by chunk, so an offline 9D score is a node's.

The bag reader (:mod:`riann_ros.bagio`) only hands over the readings; this policy is the evaluator's.
"""

from __future__ import annotations

import numpy as np

from riann_ros.magcal.input import MagConfig, pair_fields


class NodePairing:
    """A :data:`riann_ros.bagio.MagPairer` with the nodes' rule, for one pass over a bag (it carries the newest
    reading of the previous chunks into the next, so a bag read in chunks pairs like the whole bag)."""

    def __init__(self, timeout_ns: int | None = None) -> None:
        self.timeout_ns = MagConfig().timeout_ns if timeout_ns is None else timeout_ns
        self._carry: tuple[np.ndarray, np.ndarray] = (np.empty(0, np.int64), np.empty((0, 3)))

    def __call__(self, stamps: np.ndarray, mag_stamps: np.ndarray, mag: np.ndarray) -> np.ndarray:
        ts = np.concatenate([self._carry[0], np.asarray(mag_stamps, dtype=np.int64)])
        vals = np.concatenate([self._carry[1], np.asarray(mag, dtype=float).reshape(-1, 3)])
        if len(ts):
            self._carry = (ts[-1:], vals[-1:])
        return pair_fields(stamps, ts, vals, self.timeout_ns)
