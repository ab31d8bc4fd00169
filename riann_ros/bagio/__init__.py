"""rosbag2 bag I/O for IMU recordings (ROS-free: ``rosbags`` only, no rclpy).

Bag layout (the evaluator reads exactly this; see docs/converter.md, "Bag layout"):

* ``/imu/data_raw`` (``sensor_msgs/msg/Imu``): one message per IMU sample. Header stamp = log time =
  sample time; ``orientation_covariance[0] = -1`` (no orientation); ``angular_velocity`` rad/s,
  ``linear_acceleration`` m/s² (specific force, ≈ +9.81 on the up axis at rest); covariances 0
  (unknown); ``frame_id`` = the sensor frame.
* ``/ground_truth/attitude`` (``geometry_msgs/msg/QuaternionStamped``): reference orientation sensor →
  world (z up), stamped with the IMU sample it belongs to; written only where the reference is finite.
  ``frame_id`` = ``"world"``.
* ``/imu/mag`` (``sensor_msgs/msg/MagneticField``, only for recordings with a magnetometer): the field
  in tesla (REP-145), sensor frame, stamped with the IMU sample it belongs to, written only where it is
  finite; covariance 0 (unknown).
* ``/ground_truth/scored`` (``std_msgs/msg/Bool``): the score mask, written on change only: a sample
  is scored iff the last message with log time ≤ its stamp says ``True``. The first message is at
  the first sample. No such topic → every sample is scored.
* ``/dataset/info`` (``std_msgs/msg/String``): one JSON message at the first sample's time with
  ``format``, ``name``, ``dataset``, ``source``, ``frame_id``, ``samples``, ``rate_hz``, ``has_reference``,
  ``has_mag``, ``topics``, ``meta``. The
  same JSON is in ``metadata.yaml`` ``custom_data["riann_ros.info"]`` for directory bags.

A "bag" is a rosbag2 directory (``metadata.yaml`` + one storage file) or, for a target path ending in
``.mcap``, a single self-contained MCAP file (ROS 2 profile; the ``mcap`` tools and ``rosbags`` read it).

Modules: :mod:`~riann_ros.bagio.layout` (topics, types, :class:`BagError`, the type store, the info record),
:mod:`~riann_ros.bagio.cdr` (vectorised CDR serialising and parsing), :mod:`~riann_ros.bagio.atomic`
(refuse-overwrite and atomic rename), :mod:`~riann_ros.bagio.read` and :mod:`~riann_ros.bagio.write`;
:mod:`~riann_ros.bagio.repair` for bags cut off by a crash or a full disk.
Everything public is re-exported here: use ``from riann_ros import bagio; bagio.read_recording(...)``.
"""

from __future__ import annotations

from riann_ros.bagio.cdr import imu_messages, mag_messages, parse_imu, parse_mags, parse_quats, quat_messages
from riann_ros.bagio.layout import (
    BOOL_TYPE,
    COMPRESSIONS,
    IMU_TOPIC,
    IMU_TYPE,
    INFO_FORMAT,
    INFO_KEY,
    INFO_TOPIC,
    MAG_TOPIC,
    MAG_TYPE,
    QUAT_TYPE,
    REF_TOPIC,
    SCORED_TOPIC,
    STORAGES,
    STRING_TYPE,
    WORLD_FRAME,
    BagError,
    dataset_info,
    typestore,
)
from riann_ros.bagio.read import (
    MagPairer,
    bag_compression,
    bag_storage,
    concat,
    exact_stamps,
    iter_imu_chunks,
    read_info,
    read_recording,
)
from riann_ros.bagio.write import write_estimates, write_recording

__all__ = [
    "BOOL_TYPE",
    "COMPRESSIONS",
    "IMU_TOPIC",
    "IMU_TYPE",
    "INFO_FORMAT",
    "INFO_KEY",
    "INFO_TOPIC",
    "MAG_TOPIC",
    "MAG_TYPE",
    "QUAT_TYPE",
    "REF_TOPIC",
    "SCORED_TOPIC",
    "STORAGES",
    "STRING_TYPE",
    "WORLD_FRAME",
    "BagError",
    "MagPairer",
    "bag_compression",
    "bag_storage",
    "concat",
    "dataset_info",
    "exact_stamps",
    "imu_messages",
    "iter_imu_chunks",
    "mag_messages",
    "parse_imu",
    "parse_mags",
    "parse_quats",
    "quat_messages",
    "read_info",
    "read_recording",
    "typestore",
    "write_estimates",
    "write_recording",
]
