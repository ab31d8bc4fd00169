"""What the nodes publish for one estimate: ``QuaternionStamped``, ``sensor_msgs/Imu``, roll/pitch/yaw and TF.

The estimate arrives as a unit quaternion, sensor to ENU; :class:`Outputs` turns it into the world frame
(:mod:`riann_ros.frames`), applies ``yaw_offset_deg``, fills the covariance and, with
``remove_gravity_vector``, takes gravity out of ``linear_acceleration``. Topics nobody subscribes to are
not serialised.
"""

from __future__ import annotations

import math
import posixpath
from collections.abc import Callable
from typing import Any

import numpy as np
from geometry_msgs.msg import QuaternionStamped, TransformStamped, Vector3Stamped
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu

from riann_ros import frames
from riann_ros.constants import GRAVITY
from riann_ros.rotations import Quat

TF_TOPIC = "/tf"
TF_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100, reliability=ReliabilityPolicy.RELIABLE,
                    durability=DurabilityPolicy.VOLATILE)  # tf2_ros' DynamicBroadcasterQoS


def rpy_topic(attitude_topic: str) -> str:
    """The roll/pitch/yaw topic beside an attitude topic: ``imu/attitude`` -> ``imu/rpy``,
    ``imu/madgwick/attitude`` -> ``imu/madgwick/rpy``."""
    return posixpath.join(posixpath.dirname(attitude_topic), "rpy")


def make_transform(stamp: Any, parent: str, child: str, q_wxyz: Quat, reverse: bool = False) -> TransformStamped:
    """The TF the node broadcasts for one output: ``parent`` (fixed_frame) -> ``child`` (the sensor frame),
    rotation ``q_wxyz`` (the orientation in the world frame), zero translation, the input's stamp. ``reverse``:
    the inverse, ``child`` -> ``parent`` (imu_tools' reverse_tf)."""
    t = TransformStamped()
    t.header.stamp = stamp
    t.header.frame_id, t.child_frame_id = (child, parent) if reverse else (parent, child)
    r = t.transform.rotation
    w, x, y, z = (float(v) for v in q_wxyz)
    r.w, r.x, r.y, r.z = (w, -x, -y, -z) if reverse else (w, x, y, z)
    return t


def tf_frames_problem(parent: str, child: str) -> str | None:
    """Why no TF can be sent from ``parent`` to ``child``, or None when it can."""
    if not child:
        return "the input messages have an empty header.frame_id (no sensor frame to attach)"
    if child.lstrip("/") == parent.lstrip("/"):
        return f"the input's frame_id equals fixed_frame ({parent!r}): a frame cannot be its own parent"
    return None


def gravity_in_sensor(q_enu: Quat) -> tuple[float, float, float]:
    """What an accelerometer at rest reads (m/s², sensor frame) in the attitude ``q_enu`` (sensor to ENU): gravity's
    reaction, :data:`~riann_ros.constants.GRAVITY` (imu_tools' value) along the world's up axis expressed in the
    sensor frame."""
    w, x, y, z = q_enu
    return (GRAVITY * 2.0 * (x * z - w * y), GRAVITY * 2.0 * (y * z + w * x), GRAVITY * (1.0 - 2.0 * (x * x + y * y)))


def yaw_rotated(q: Quat, yaw_rad: float) -> Quat:
    """``Rz(yaw_rad) ⊗ q``: ``q`` turned about its world frame's z axis."""
    c, s = math.cos(0.5 * yaw_rad), math.sin(0.5 * yaw_rad)
    w, x, y, z = q
    return c * w - s * z, c * x - s * y, c * y + s * x, c * z + s * w


def model_covariance(sigma: Any) -> list[float]:
    """The orientation covariance (row-major 3 × 3 about the world x, y, z axes) of the σ (rad) an estimator reports:
    ``diag(σ_i², σ_i², σ_ψ²)``. The inclination's σ is the same about both horizontal axes, so the matrix is the
    same in ENU, NED and NWU and after ``yaw_offset_deg``; positive definite for σ > 0."""
    i2 = float(sigma[0]) ** 2
    return [i2, 0.0, 0.0, 0.0, i2, 0.0, 0.0, 0.0, float(sigma[1]) ** 2]


def orientation_covariances(p: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """(covariance while the heading follows the gyro only, while a magnetometer field corrects it)."""
    rp = math.radians(p["roll_pitch_stddev_deg"]) ** 2
    return tuple(np.array([rp, 0.0, 0.0, 0.0, rp, 0.0, 0.0, 0.0, math.radians(p[k]) ** 2])  # type: ignore[return-value]
                 for k in ("yaw_stddev_deg", "mag_yaw_stddev_deg"))


class Outputs:
    """The output publishers of one node and the per-message publishing. ``p``: the node's parameter values;
    ``warn(key, text)`` logs a throttled warning."""

    def __init__(self, node: Node, attitude_topic: str, imu_topic: str, p: dict[str, Any],
                 warn: Callable[[str, str], None]) -> None:
        qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=int(p["output_depth"]),
                         reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
        self.topics = [attitude_topic, imu_topic, *([rpy_topic(attitude_topic)] if p["publish_rpy"] else [])]
        self._att_pub = node.create_publisher(QuaternionStamped, attitude_topic, qos)
        self._imu_pub = node.create_publisher(Imu, imu_topic, qos)
        self._rpy_pub = node.create_publisher(Vector3Stamped, rpy_topic(attitude_topic), qos) \
            if p["publish_rpy"] else None
        self.world = frames.check_world_frame(p["world_frame"])
        self._model = True
        self.fixed_frame = str(p["fixed_frame"])
        self._warn = warn
        self._att = QuaternionStamped()
        self._att.header.frame_id = self.fixed_frame
        self._rpy = Vector3Stamped()
        self._rpy.header.frame_id = self.fixed_frame
        self.configure(p)
        self._reverse_tf = bool(p["reverse_tf"])
        self._tf_pub, self._tf_type = self._tf_publisher(node, bool(p["publish_tf"]))

    def configure(self, p: dict[str, Any]) -> None:
        """Apply the run-time output parameters in ``p`` (covariances, yaw offset, gravity removal)."""
        if "roll_pitch_stddev_deg" in p:
            self.covariances = orientation_covariances(p)
        if "orientation_covariance" in p:
            self._model = p["orientation_covariance"] == "model"
        if "yaw_offset_deg" in p:
            self._yaw_offset = math.radians(p["yaw_offset_deg"])
        if "remove_gravity_vector" in p:
            self._remove_gravity = bool(p["remove_gravity_vector"])

    def _tf_publisher(self, node: Node, enabled: bool) -> tuple[Any, Any]:
        """(/tf publisher, TFMessage type), or (None, None) when TF is off or tf2_msgs cannot be imported."""
        if not enabled:
            return None, None
        try:
            from tf2_msgs.msg import TFMessage
        except ImportError as e:
            node.get_logger().warning(f"publish_tf: tf2_msgs not available ({e}); not broadcasting TF")
            return None, None
        direction = "<input frame_id> -> '{}'" if self._reverse_tf else "'{}' -> <input frame_id>"
        node.get_logger().info(f"publish_tf: broadcasting {direction.format(self.fixed_frame)} on {TF_TOPIC}")
        return node.create_publisher(TFMessage, TF_TOPIC, TF_QOS), TFMessage

    def world_orientation(self, q_enu: Quat) -> Quat:
        """The published orientation of an estimate ``q_enu``: in the world frame, turned by ``yaw_offset_deg``."""
        q = frames.to_world_scalar(*q_enu, self.world)
        return yaw_rotated(q, self._yaw_offset) if self._yaw_offset else q

    def publish(self, msg: Imu, q_enu: Quat, heading_observed: bool, sigma: Any = None) -> None:
        """Publish the estimate ``q_enu`` (w, x, y, z, sensor to ENU) of the input ``msg``; ``sigma``: the
        estimator's σ (rad) of its inclination and heading, used with ``orientation_covariance: model``."""
        q = self.world_orientation(q_enu)
        att = self._att
        att.header.stamp = msg.header.stamp
        o = att.quaternion
        o.w, o.x, o.y, o.z = q
        # serialising costs most of the callback: skip topics nobody subscribes to
        if self._att_pub.get_subscription_count():
            self._att_pub.publish(att)
        if self._rpy_pub is not None and self._rpy_pub.get_subscription_count():
            rpy = self._rpy
            rpy.header.stamp = msg.header.stamp
            v = rpy.vector
            v.x, v.y, v.z = frames.rpy_deg_scalar(*q)
            self._rpy_pub.publish(rpy)
        if self._tf_pub is not None:
            self._publish_tf(msg.header.stamp, msg.header.frame_id, q)
        if self._imu_pub.get_subscription_count():
            msg.orientation = o
            msg.orientation_covariance = (model_covariance(sigma) if self._model and sigma is not None
                                          else self.covariances[heading_observed])
            if self._remove_gravity:
                a = msg.linear_acceleration
                gx, gy, gz = gravity_in_sensor(q_enu)
                a.x, a.y, a.z = a.x - gx, a.y - gy, a.z - gz
            self._imu_pub.publish(msg)

    def _publish_tf(self, stamp: Any, child: str, q: Quat) -> None:
        problem = tf_frames_problem(self.fixed_frame, child)
        if problem is not None:
            self._warn("tf", f"publish_tf: not broadcasting TF: {problem}")
            return
        self._tf_pub.publish(self._tf_type(transforms=[make_transform(stamp, self.fixed_frame, child, q,
                                                                      self._reverse_tf)]))
