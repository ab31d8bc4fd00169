"""The bag layout: topic names and types, the ``/dataset/info`` record, :class:`BagError` and the type store.

The layout itself is described in the :mod:`riann_ros.bagio` package docstring.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from riann_ros.recording import Recording

IMU_TOPIC = "/imu/data_raw"
REF_TOPIC = "/ground_truth/attitude"
SCORED_TOPIC = "/ground_truth/scored"
INFO_TOPIC = "/dataset/info"
MAG_TOPIC = "/imu/mag"
IMU_TYPE = "sensor_msgs/msg/Imu"
MAG_TYPE = "sensor_msgs/msg/MagneticField"
QUAT_TYPE = "geometry_msgs/msg/QuaternionStamped"
BOOL_TYPE = "std_msgs/msg/Bool"
STRING_TYPE = "std_msgs/msg/String"
WORLD_FRAME = "world"
INFO_FORMAT = "riann_ros/bag/1"
INFO_KEY = "riann_ros.info"
STORAGES = ("mcap", "sqlite3")
COMPRESSIONS = (None, "zstd")

_TYPESTORE = None


class BagError(Exception):
    """A bag that cannot be read as an IMU recording; the message names the bag and the problem."""

    def __init__(self, path: str | os.PathLike[str], problem: str) -> None:
        self.path = Path(path)
        self.problem = problem
        super().__init__(f"{path}: {problem}")


def typestore():
    """The ROS 2 Jazzy type store (cached)."""
    global _TYPESTORE
    if _TYPESTORE is None:
        from rosbags.typesys import Stores, get_typestore

        _TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
    return _TYPESTORE


def dataset_info(rec: Recording) -> dict:
    """The JSON-able dict written to ``/dataset/info``."""
    rate = rec.rate_hz
    return {
        "format": INFO_FORMAT,
        "name": rec.name,
        "dataset": rec.dataset,
        "source": rec.source,
        "frame_id": rec.frame_id,
        "samples": len(rec),
        "rate_hz": None if not np.isfinite(rate) else rate,
        "has_reference": rec.quat_ref is not None,
        "has_mag": rec.mag is not None,
        "topics": {"imu": IMU_TOPIC, "reference": REF_TOPIC, "scored": SCORED_TOPIC,
                   **({"mag": MAG_TOPIC} if rec.mag is not None else {})},
        "meta": {str(k): str(v) for k, v in rec.meta.items()},
    }
