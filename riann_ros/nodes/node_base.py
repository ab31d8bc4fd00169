"""The one ROS 2 node base behind riann_node, madgwick_node, mahony_node and vqf_node.

It owns everything ROS: the ``imu/data_raw`` subscription and its QoS, parameters (node parameters
plus every :class:`~riann_ros.estimators.base.ParamSpec` of the estimator), the ``~/reset`` service,
publishing ``QuaternionStamped``, ``sensor_msgs/Imu``, roll/pitch/yaw and TF in the chosen world frame
(:mod:`riann_ros.frames`), the stamp-rate check, and ``/diagnostics``. What to do with a
sample (dt from stamps, input checks, resets) is decided by the ROS-free
:class:`~riann_ros.stream.EstimatorStream`, the same code the offline evaluator runs.

A concrete node only names its estimator and its default output topics.
"""

from __future__ import annotations

import math
import posixpath
import statistics
import sys
import time
from collections import Counter
from typing import Any, ClassVar

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import QuaternionStamped, TransformStamped, Vector3Stamped
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu, MagneticField
from std_srvs.srv import Trigger

from riann_ros import frames, stamps
from riann_ros import mag as mg
from riann_ros import stream as st
from riann_ros.estimators import create, estimator_class
from riann_ros.params import ParamSpec

INPUT_TOPIC = "imu/data_raw"
MAG_TOPIC = "imu/mag"
QOS_CHOICES = ("sensor_data", "reliable", "best_effort")
THROTTLE_S = 5.0  # at most one warning per rejection reason in this many seconds

#: Parameters of the node itself (the gate's come from :data:`riann_ros.stream.GATE_PARAMS`, the
#: estimator's from its ``PARAMS``); those with ``runtime=False`` only take effect at start-up.
NODE_ONLY_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec("input_qos", "sensor_data", "Input QoS: sensor_data (best effort, connects to reliable and "
              "best-effort drivers), best_effort, or reliable.", choices=QOS_CHOICES),
    ParamSpec("input_depth", 1000, "Input queue depth (keep last): a burst larger than this loses its oldest "
              "messages in DDS before the node sees them.", min=1, max=100000),
    ParamSpec("output_depth", 1000, "Output queue depth (keep last, reliable): outputs not yet acknowledged by a "
              "slow subscriber are dropped once more than this many are queued.", min=1, max=100000),
    ParamSpec("roll_pitch_stddev_deg", 2.0, "deg; standard deviation written to the roll and pitch entries of the "
              "orientation covariance of imu/data.", min=0.0, max=180.0, runtime=True),
    ParamSpec("yaw_stddev_deg", 180.0, "deg; standard deviation written to the yaw entry of the orientation "
              "covariance while the heading is not tied to a magnetometer (it is unobservable: gyro drift only).",
              min=0.0, max=1.0e6, runtime=True),
    ParamSpec("mag_yaw_stddev_deg", 5.0, "deg; standard deviation of the yaw entry while the heading is corrected "
              "by an undisturbed magnetometer field (9D).", min=0.0, max=1.0e6, runtime=True),
    ParamSpec("diagnostics_period", 1.0, "s; period of /diagnostics messages.", min=0.05, max=3600.0),
    ParamSpec("world_frame", frames.ENU, "World frame of the published orientation (imu/attitude, imu/data, imu/rpy, "
              "TF): enu (x east, y north, z up; REP-103), ned (x north, y east, z down) or nwu (x north, y west, "
              "z up); the physical change of axes from ENU (docs/node.md, Frames).", choices=frames.WORLD_FRAMES),
    ParamSpec("fixed_frame", "odom", "frame_id of imu/attitude and imu/rpy (a QuaternionStamped is expressed in its "
              "header frame: the world frame, not the sensor's) and parent frame of the TF; imu/data keeps the "
              "input's sensor frame."),
    ParamSpec("publish_tf", False, "Broadcast fixed_frame -> the input's frame_id on /tf (rotation only, zero "
              "translation; for visualising a stand-alone IMU). Needs tf2_msgs (a system ROS 2)."),
    ParamSpec("publish_rpy", False, "Publish roll, pitch, yaw in degrees (ZYX, in world_frame) as "
              "geometry_msgs/Vector3Stamped on imu/rpy (x = roll, y = pitch, z = yaw), for plotting."),
)
NODE_PARAMS: tuple[ParamSpec, ...] = (*st.GATE_PARAMS, *mg.MAG_PARAMS, *NODE_ONLY_PARAMS)
COVARIANCE_PARAMS = ("roll_pitch_stddev_deg", "yaw_stddev_deg", "mag_yaw_stddev_deg")


RATE_CHECK_SAMPLES = 100  # accepted samples (restarts excluded) whose median dt gives the measured stamp rate
RATE_TOLERANCE = 0.10  # relative difference between measured and nominal rate that is warned about
TF_TOPIC = "/tf"
TF_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100, reliability=ReliabilityPolicy.RELIABLE,
                    durability=DurabilityPolicy.VOLATILE)  # tf2_ros' DynamicBroadcasterQoS


def _descriptor(spec: ParamSpec) -> ParameterDescriptor:
    d = ParameterDescriptor(description=spec.description, read_only=not spec.runtime)
    if spec.min is not None and spec.max is not None and not isinstance(spec.default, bool | tuple):
        if isinstance(spec.default, int):
            d.integer_range = [IntegerRange(from_value=int(spec.min), to_value=int(spec.max), step=1)]
        elif isinstance(spec.default, float):
            lo, hi = float(spec.min), float(spec.max)
            d.floating_point_range = [FloatingPointRange(from_value=lo, to_value=hi, step=0.0)]
    return d


def rpy_topic(attitude_topic: str) -> str:
    """The roll/pitch/yaw topic beside an attitude topic: ``imu/attitude`` -> ``imu/rpy``,
    ``imu/madgwick/attitude`` -> ``imu/madgwick/rpy``."""
    return posixpath.join(posixpath.dirname(attitude_topic), "rpy")


def make_transform(stamp: Any, parent: str, child: str, q_wxyz: tuple[float, float, float, float]) -> TransformStamped:
    """The TF the node broadcasts for one output: ``parent`` (fixed_frame) -> ``child`` (the sensor frame),
    rotation ``q_wxyz`` (the orientation in the world frame), zero translation, the input's stamp."""
    t = TransformStamped()
    t.header.stamp = stamp
    t.header.frame_id = parent
    t.child_frame_id = child
    r = t.transform.rotation
    r.w, r.x, r.y, r.z = (float(v) for v in q_wxyz)
    return t


def tf_frames_problem(parent: str, child: str) -> str | None:
    """Why no TF can be sent from ``parent`` to ``child``, or None when it can."""
    if not child:
        return "the input messages have an empty header.frame_id (no sensor frame to attach)"
    if child.lstrip("/") == parent.lstrip("/"):
        return f"the input's frame_id equals fixed_frame ({parent!r}): a frame cannot be its own parent"
    return None


class StampRateCheck:
    """The IMU's stamp rate, measured once: the median dt over the first ``samples`` accepted samples that
    continue a sequence (the first sample after a (re)start gets dt = 1/nominal_rate, so it is left out).
    The median ignores the odd gap, burst or jittery stamp."""

    def __init__(self, samples: int = RATE_CHECK_SAMPLES, tolerance: float = RATE_TOLERANCE) -> None:
        self.samples = samples
        self.tolerance = tolerance
        self.measured_hz: float | None = None
        self._dts: list[float] = []

    def add(self, dt: float) -> bool:
        """Count one dt (s); True when this one completes the measurement."""
        if self.measured_hz is not None or not dt > 0.0:
            return False
        self._dts.append(dt)
        if len(self._dts) < self.samples:
            return False
        self.measured_hz = 1.0 / statistics.median(self._dts)
        self._dts = []
        return True

    def mismatch(self, nominal_hz: float) -> float | None:
        """Relative difference measured/nominal − 1 when it exceeds the tolerance, else None."""
        if self.measured_hz is None:
            return None
        rel = self.measured_hz / nominal_hz - 1.0
        return rel if abs(rel) > self.tolerance else None

    def text(self, nominal_hz: float) -> str:
        rel = self.mismatch(nominal_hz) or 0.0
        return (f"measured IMU stamp rate {self.measured_hz:.1f} Hz (median dt of {self.samples} samples) differs "
                f"from nominal_rate {nominal_hz:.1f} Hz by {rel * 100:+.0f} %: set the parameter nominal_rate to "
                f"{self.measured_hz:.1f} (dt of the first sample after a (re)start; VQF's sample time, its time "
                "constants scale with it)")


def input_qos(kind: str, depth: int) -> QoSProfile:
    if kind not in QOS_CHOICES:
        raise ValueError(f"input_qos must be one of {', '.join(QOS_CHOICES)}, got {kind!r}")
    reliability = ReliabilityPolicy.RELIABLE if kind == "reliable" else ReliabilityPolicy.BEST_EFFORT
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=reliability,
                      durability=DurabilityPolicy.VOLATILE)


class EstimatorNode(Node):
    """Subscribe IMU samples, estimate attitude, publish it. Subclasses set the class attributes."""

    ESTIMATOR: ClassVar[str] = ""
    NODE_NAME: ClassVar[str] = ""
    ATTITUDE_TOPIC: ClassVar[str] = "imu/attitude"
    IMU_TOPIC: ClassVar[str] = "imu/data"

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(self.NODE_NAME, **kwargs)
        cls = estimator_class(self.ESTIMATOR)
        self._specs: dict[str, ParamSpec] = {p.name: p for p in cls.PARAMS}
        self._node_specs = {p.name: p for p in NODE_PARAMS}
        self._float_params = {s.name for s in (*NODE_PARAMS, *cls.PARAMS) if isinstance(s.default, float | tuple)}
        for spec in (*NODE_PARAMS, *cls.PARAMS):
            self._declare(spec)
        p = {name: self.get_parameter(name).value for name in [*self._node_specs, *self._specs]}
        for name, spec in self._node_specs.items():
            p[name] = spec.validate(p[name])
        if not p["fixed_frame"].strip("/ "):
            raise ValueError("fixed_frame must not be empty")
        self.stream = st.EstimatorStream(create(self.ESTIMATOR, **{k: p[k] for k in self._specs}),
                                         self._gate_config(p), self._mag_config(p))
        self._covariances = self._orientation_covariances(p)
        self._world = frames.check_world_frame(p["world_frame"])
        self._fixed_frame = str(p["fixed_frame"])
        self.add_pre_set_parameters_callback(self._int_to_float)
        self.add_on_set_parameters_callback(self._on_set_parameters)

        out_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=int(p["output_depth"]),
                             reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
        self._pub_att = self.create_publisher(QuaternionStamped, self.ATTITUDE_TOPIC, out_qos)
        self._pub_imu = self.create_publisher(Imu, self.IMU_TOPIC, out_qos)
        self._pub_rpy = self.create_publisher(Vector3Stamped, rpy_topic(self.ATTITUDE_TOPIC), out_qos) \
            if p["publish_rpy"] else None
        self._pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_subscription(Imu, INPUT_TOPIC, self._on_imu, input_qos(p["input_qos"], int(p["input_depth"])))
        self._mag = mg.MagPairing()
        self._mag_state = ""  # the field state last logged
        if p["use_mag"] != "false" and self.stream.estimator.USES_MAG:
            self.create_subscription(MagneticField, MAG_TOPIC, self._on_mag,
                                     input_qos(p["input_qos"], int(p["input_depth"])))
        self.create_service(Trigger, "~/reset", self._on_reset)
        self.create_timer(float(p["diagnostics_period"]), self._publish_diagnostics)

        self._att_msg = QuaternionStamped()
        self._att_msg.header.frame_id = self._fixed_frame
        self._rpy_msg = Vector3Stamped()
        self._rpy_msg.header.frame_id = self._fixed_frame
        self._last_warn: dict[str, float] = {}
        self._period_start = time.monotonic()
        self._period_in = 0
        self._period_rejected: Counter[str] = Counter()
        self._proc_us: list[float] = []
        self._est_us: list[float] = []
        self._frame_id = ""
        self._rate = StampRateCheck()
        mag_text = (f"; magnetometer on '{self.resolve_topic_name(MAG_TOPIC)}' (use_mag={p['use_mag']})"
                    if p["use_mag"] != "false" and self.stream.estimator.USES_MAG else "; magnetometer not used")
        outputs = [self.ATTITUDE_TOPIC, self.IMU_TOPIC, *([rpy_topic(self.ATTITUDE_TOPIC)] if p["publish_rpy"] else [])]
        self.get_logger().info(
            f"{self.ESTIMATOR} estimator on '{self.resolve_topic_name(INPUT_TOPIC)}' -> "
            + ", ".join(f"'{self.resolve_topic_name(t)}'" for t in outputs)
            + f"; orientation in {self._world.upper()} (world_frame), imu/attitude in frame '{self._fixed_frame}'"
            + mag_text
            + "; parameters: " + ", ".join(f"{k}={v}" for k, v in p.items())
        )
        self._pub_tf, self._tf_type = self._tf_publisher(bool(p["publish_tf"]))

    # -- parameters -----------------------------------------------------------------------------
    def _declare(self, spec: ParamSpec) -> None:
        """Declare one parameter from its spec. A float parameter also takes an integer (``-p nominal_rate:=200``,
        ``nominal_rate: 200`` in a params file): the start-up value is read through a dynamically typed probe,
        converted and checked by the spec (clear errors for wrong types and ranges), and the parameter is then
        declared as a double holding that value."""
        if not isinstance(spec.default, float | tuple):
            self.declare_parameter(spec.name, spec.default, _descriptor(spec))
            return
        default = list(spec.default) if isinstance(spec.default, tuple) else spec.default
        raw = self.declare_parameter(spec.name, default, ParameterDescriptor(dynamic_typing=True)).value
        self.undeclare_parameter(spec.name)
        value = spec.validate(list(raw) if isinstance(spec.default, tuple) else raw)
        self.declare_parameter(spec.name, list(value) if isinstance(value, tuple) else value, _descriptor(spec),
                               ignore_override=True)

    def _int_to_float(self, params: list[Parameter]) -> list[Parameter]:
        """Run-time sets: an integer for a float parameter becomes a double (its range is then checked)."""
        out = []
        for prm in params:
            if prm.name in self._float_params and prm.type_ == Parameter.Type.INTEGER:
                prm = Parameter(prm.name, Parameter.Type.DOUBLE, float(prm.value))
            elif prm.name in self._float_params and prm.type_ == Parameter.Type.INTEGER_ARRAY:
                prm = Parameter(prm.name, Parameter.Type.DOUBLE_ARRAY, [float(v) for v in prm.value])
            out.append(prm)
        return out

    @staticmethod
    def _gate_config(p: dict[str, Any]) -> st.GateConfig:
        return st.GateConfig(**{spec.name: p[spec.name] for spec in st.GATE_PARAMS})

    @staticmethod
    def _mag_config(p: dict[str, Any]) -> mg.MagConfig:
        return mg.MagConfig(**{spec.name: p[spec.name] for spec in mg.MAG_PARAMS})

    @staticmethod
    def _orientation_covariances(p: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
        """(covariance while the heading follows the gyro only, while a magnetometer field corrects it)."""
        rp = math.radians(p["roll_pitch_stddev_deg"]) ** 2
        return tuple(np.array([rp, 0.0, 0.0, 0.0, rp, 0.0, 0.0, 0.0, math.radians(p[k]) ** 2])  # type: ignore[return-value]
                     for k in ("yaw_stddev_deg", "mag_yaw_stddev_deg"))

    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        est_changes: dict[str, Any] = {}
        gate = dict(self.stream.gate.config.__dict__)
        mag = dict(self.stream.mag.config.__dict__)
        cov = None
        try:
            for prm in params:
                if prm.name in self._specs:
                    spec = self._specs[prm.name]
                    if not spec.runtime:
                        return SetParametersResult(successful=False, reason=f"{prm.name} is read-only at run time")
                    est_changes[prm.name] = spec.validate(prm.value)
                elif prm.name in gate:
                    gate[prm.name] = prm.value
                elif prm.name in mag:
                    mag[prm.name] = tuple(prm.value) if isinstance(mag[prm.name], tuple) else prm.value
                elif prm.name in COVARIANCE_PARAMS:
                    cur = {n: self.get_parameter(n).value for n in COVARIANCE_PARAMS}
                    cur[prm.name] = self._node_specs[prm.name].validate(prm.value)
                    cov = self._orientation_covariances(cur)
            new_gate = st.GateConfig(**gate)
            new_mag = mg.MagConfig(**mag)
            if est_changes:
                self.stream.estimator.set_params(**est_changes)
        except (ValueError, TypeError) as e:
            return SetParametersResult(successful=False, reason=str(e))
        self.stream.gate.config = new_gate
        self.stream.mag.config = new_mag
        if cov is not None:
            self._covariances = cov
        self.get_logger().info("parameters changed: " + ", ".join(f"{p.name}={p.value}" for p in params))
        return SetParametersResult(successful=True)

    # -- TF -------------------------------------------------------------------------------------
    def _tf_publisher(self, enabled: bool) -> tuple[Any, Any]:
        """(/tf publisher, TFMessage type), or (None, None) when TF is off or tf2_msgs cannot be imported."""
        if not enabled:
            return None, None
        try:
            from tf2_msgs.msg import TFMessage
        except ImportError as e:
            self.get_logger().warning(f"publish_tf: tf2_msgs not available ({e}); not broadcasting TF")
            return None, None
        self.get_logger().info(f"publish_tf: broadcasting '{self._fixed_frame}' -> <input frame_id> on {TF_TOPIC}")
        return self.create_publisher(TFMessage, TF_TOPIC, TF_QOS), TFMessage

    def _publish_tf(self, stamp: Any, child: str, q: tuple[float, float, float, float]) -> None:
        problem = tf_frames_problem(self._fixed_frame, child)
        if problem is not None:
            self._warn_throttled("tf", f"publish_tf: not broadcasting TF: {problem}")
            return
        self._pub_tf.publish(self._tf_type(transforms=[make_transform(stamp, self._fixed_frame, child, q)]))

    # -- data path ------------------------------------------------------------------------------
    def _on_imu(self, msg: Imu) -> None:
        t0 = time.perf_counter_ns()
        stamp = msg.header.stamp
        stamp_ns = stamps.to_ns(stamp)
        la, av = msg.linear_acceleration, msg.angular_velocity
        acc = (la.x, la.y, la.z)
        gyr = (av.x, av.y, av.z)
        receive_ns = self.get_clock().now().nanoseconds if stamp_ns == 0 else None
        self._period_in += 1
        t1 = time.perf_counter_ns()
        field = self._mag.at(stamp_ns, self.stream.mag.config.timeout_ns)[0] if self._mag.received else None
        q, r = self.stream.process(stamp_ns, acc, gyr, receive_ns, field)
        self._est_us.append((time.perf_counter_ns() - t1) * 1e-3)
        if self._mag_state != self.stream.mag.state:
            self._log_mag_state()
        self._log_gate_result(r)
        if q is None:
            self._period_rejected[r.reason or "?"] += 1
            self._warn_throttled(r.reason or "?", f"sample rejected ({r.reason}) at stamp {r.stamp_ns * 1e-9:.6f} s")
            return
        if r.reset is None and self._rate.add(r.dt):
            self._check_rate()
        if stamp_ns == 0:  # publish with the receive time we used
            stamps.set_ns(stamp, r.stamp_ns)
        self._frame_id = msg.header.frame_id
        self._publish(msg, frames.to_world_scalar(float(q[0]), float(q[1]), float(q[2]), float(q[3]), self._world))
        self._proc_us.append((time.perf_counter_ns() - t0) * 1e-3)

    def _on_mag(self, msg: MagneticField) -> None:
        f = msg.magnetic_field
        self._mag.push(stamps.to_ns(msg.header.stamp), (f.x, f.y, f.z))

    def _log_mag_state(self) -> None:
        """Log the switches between 9D and 6D (auto: as they happen; the reason is in /diagnostics too)."""
        old, new = self._mag_state, self.stream.mag.state
        self._mag_state = new
        if new == mg.FIELD_NONE and old in ("", mg.FIELD_NONE):
            return  # no magnetometer so far: nothing to say (the start-up line names the topic)
        text = f"magnetometer: {new}" + ("" if new == mg.FIELD_USED else " (heading held by the gyro)")
        if new == mg.FIELD_USED or self.stream.mag.config.use_mag == "auto":
            self.get_logger().info(text)
        else:
            self.get_logger().warning(text)

    def _log_gate_result(self, r: st.GateResult) -> None:
        for w in r.warnings:
            self.get_logger().warning(st.WARNING_TEXT[w])
        if r.reset in (st.GAP, st.CLOCK_JUMP):
            self.get_logger().info(f"{r.reset.replace('_', ' ')} at stamp {r.stamp_ns * 1e-9:.6f} s: estimator "
                                   "restarted, re-initialised from this sample")

    def _publish(self, msg: Imu, q: tuple[float, float, float, float]) -> None:
        """Publish the orientation ``q`` (w, x, y, z, in the world frame) of the input ``msg``."""
        att = self._att_msg
        att.header.stamp = msg.header.stamp
        o = att.quaternion
        o.w, o.x, o.y, o.z = q
        # serialising costs most of the callback: skip topics nobody subscribes to
        if self._pub_att.get_subscription_count():
            self._pub_att.publish(att)
        if self._pub_rpy is not None and self._pub_rpy.get_subscription_count():
            rpy = self._rpy_msg
            rpy.header.stamp = msg.header.stamp
            v = rpy.vector
            v.x, v.y, v.z = frames.rpy_deg_scalar(*q)
            self._pub_rpy.publish(rpy)
        if self._pub_tf is not None:
            self._publish_tf(msg.header.stamp, msg.header.frame_id, q)
        if self._pub_imu.get_subscription_count():
            msg.orientation = o
            msg.orientation_covariance = self._covariances[self.stream.estimator.heading_observed()]
            self._pub_imu.publish(msg)

    def _check_rate(self) -> None:
        nominal = self.stream.gate.config.nominal_rate
        if self._rate.mismatch(nominal) is not None:
            self.get_logger().warning(self._rate.text(nominal))

    def _warn_throttled(self, key: str, text: str) -> None:
        now = time.monotonic()
        if now - self._last_warn.get(key, -math.inf) >= THROTTLE_S:
            self._last_warn[key] = now
            self.get_logger().warning(text + " (throttled: one message per reason every 5 s; counts in /diagnostics)")

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        self.stream.reset()
        self._mag.clear()
        self.get_logger().info("reset requested: estimator state cleared")
        response.success = True
        response.message = f"{self.ESTIMATOR} estimator reset; re-initialising from the next sample"
        return response

    # -- diagnostics ----------------------------------------------------------------------------
    def _diagnostic_level(self) -> tuple[bytes, str]:
        """(level, message) of this period: no input, rejections, a nominal_rate far from the stamp rate."""
        problems = []
        if self._period_in == 0:
            problems.append("no input on " + self.resolve_topic_name(INPUT_TOPIC))
        if sum(self._period_rejected.values()):
            problems.append("samples rejected: " + ", ".join(f"{k}={v}" for k, v in self._period_rejected.items()))
        nominal = self.stream.gate.config.nominal_rate
        if self._rate.mismatch(nominal) is not None:
            problems.append(f"nominal_rate {nominal:.1f} Hz differs from the measured stamp rate "
                            f"{self._rate.measured_hz:.1f} Hz: set nominal_rate")
        mag = self.stream.mag
        if mag.config.use_mag == "true" and self.stream.estimator.USES_MAG and mag.state != mg.FIELD_USED:
            problems.append(f"use_mag is true but {mag.state[4:]} on {self.resolve_topic_name(MAG_TOPIC)}")
        if problems:
            return DiagnosticStatus.WARN, "; ".join(problems)
        return DiagnosticStatus.OK, "ok"

    def _publish_diagnostics(self) -> None:
        now = time.monotonic()
        period = max(now - self._period_start, 1e-9)
        gate = self.stream.gate
        dts = gate.pop_dt_stats()
        proc = np.asarray(self._proc_us)
        est = np.asarray(self._est_us)
        rate = self._period_in / period
        status = DiagnosticStatus()
        status.name = f"{self.get_name()}: {self.ESTIMATOR} attitude estimator"
        status.hardware_id = self._frame_id
        status.level, status.message = self._diagnostic_level()
        measured = self._rate.measured_hz
        values = {
            "input rate (Hz)": f"{rate:.2f}",
            "stamp rate measured (Hz)": f"{measured:.2f}" if measured is not None else "nan",
            "nominal_rate (Hz)": f"{gate.config.nominal_rate:.2f}",
            "dt min (ms)": f"{dts.get('min', math.nan) * 1e3:.3f}",
            "dt mean (ms)": f"{dts.get('mean', math.nan) * 1e3:.3f}",
            "dt max (ms)": f"{dts.get('max', math.nan) * 1e3:.3f}",
            "dt std (ms)": f"{dts.get('std', math.nan) * 1e3:.3f}",
            "samples accepted (total)": str(gate.accepted),
            "inference time mean (us)": f"{est.mean():.1f}" if len(est) else "nan",
            "inference time max (us)": f"{est.max():.1f}" if len(est) else "nan",
            "processing time mean (us)": f"{proc.mean():.1f}" if len(proc) else "nan",
            "processing time p99 (us)": f"{np.percentile(proc, 99):.1f}" if len(proc) else "nan",
            "processing time max (us)": f"{proc.max():.1f}" if len(proc) else "nan",
            "world frame": self._world,
            "magnetometer": self.stream.mag.state if self.stream.estimator.USES_MAG else "not used by this estimator",
            "field readings received (total)": str(self._mag.received),
            "heading": "magnetic (9D)" if self.stream.estimator.heading_observed() else "gyro only",
        }
        values.update(self.stream.estimator.diagnostics())
        for reason in st.REJECT_REASONS:
            values[f"rejected {reason} (total)"] = str(gate.rejected[reason])
        for cause in (st.GAP, st.CLOCK_JUMP):
            values[f"restarts {cause} (total)"] = str(gate.resets[cause])
        status.values = [KeyValue(key=k, value=v) for k, v in values.items()]
        arr = DiagnosticArray()
        arr.header.stamp = self.get_clock().now().to_msg()
        arr.status = [status]
        self._pub_diag.publish(arr)
        self._period_start = now
        self._period_in = 0
        self._period_rejected.clear()
        self._proc_us = []
        self._est_us = []


def run(node_cls: type[EstimatorNode], args: list[str] | None = None) -> int:
    """Entry point shared by all node executables: init, spin until Ctrl-C / shutdown, clean up."""
    rclpy.init(args=args if args is not None else sys.argv)
    node = None
    try:
        node = node_cls()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception as e:  # start-up errors: a clear message, non-zero exit
        print(f"{node_cls.NODE_NAME}: error: {e}", file=sys.stderr)
        return 1
    finally:
        if node is not None:
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0
