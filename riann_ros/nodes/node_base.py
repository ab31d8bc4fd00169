"""The one ROS 2 node base behind riann_node, madgwick_node, mahony_node and vqf_node.

It owns the ROS side of one estimator: the ``imu/data_raw`` and ``imu/mag`` subscriptions and their QoS, the
parameters (:mod:`riann_ros.nodes.parameters`), the ``~/reset`` and ``~/restart`` services, the saved magnetometer
calibration (``mag_calibration_file``, ``~/save_mag_calibration``: :mod:`riann_ros.nodes.mag_calibration`), the
outputs (:mod:`riann_ros.nodes.outputs`) and ``/diagnostics`` (:mod:`riann_ros.nodes.diagnostics`). What to do with
a sample (dt from stamps, input checks, resets) is decided by the ROS-free
:class:`~riann_ros.stream.EstimatorStream`, the same code the offline evaluator runs.

A concrete node only names its estimator and its default output topics.
"""

from __future__ import annotations

import functools
import gc
import os
import sys
import time
from typing import Any, ClassVar

import rclpy
from rcl_interfaces.msg import SetParametersResult
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu, MagneticField
from std_srvs.srv import Trigger

from riann_ros import gate as gt
from riann_ros import stamps
from riann_ros import stream as st
from riann_ros.estimators import create, estimator_class
from riann_ros.magcal import input as mg
from riann_ros.magcal.records import MagCalPrior
from riann_ros.nodes import ros_args, usage
from riann_ros.nodes.diagnostics import Diagnostics
from riann_ros.nodes.mag_calibration import SAVE_FORCE_SERVICE, SAVE_SERVICE, CalibrationFile, check_changes, start_file
from riann_ros.nodes.node_log import INPUT_TOPIC, MAG_TOPIC, NodeLog
from riann_ros.nodes.outputs import Outputs, rpy_topic
from riann_ros.nodes.parameters import NODE_PARAMS, QOS_CHOICES, NodeParameters, collect_changes

DRAIN_MAX = 64  # IMU messages already queued that one callback takes on (the executor's per-message overhead)


def input_qos(kind: str, depth: int) -> QoSProfile:
    if kind not in QOS_CHOICES:
        raise ValueError(f"input_qos must be one of {', '.join(QOS_CHOICES)}, got {kind!r}")
    reliability = ReliabilityPolicy.RELIABLE if kind == "reliable" else ReliabilityPolicy.BEST_EFFORT
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=reliability,
                      durability=DurabilityPolicy.VOLATILE)


class EstimatorNode(NodeLog):
    """Subscribe IMU samples, estimate attitude, publish it. Subclasses set the class attributes.

    ``params_files`` (the ``--params-file`` paths of the command line) lets the node warn about sections of those
    files that do not apply to it; ``notes`` are start-up remarks on the arguments to log."""

    ESTIMATOR: ClassVar[str] = ""
    NODE_NAME: ClassVar[str] = ""
    ATTITUDE_TOPIC: ClassVar[str] = "imu/attitude"
    IMU_TOPIC: ClassVar[str] = "imu/data"

    def __init__(self, params_files: list[str] | None = None, notes: list[str] | None = None, **kwargs: Any) -> None:
        super().__init__(self.NODE_NAME, **kwargs)
        est_specs = estimator_class(self.ESTIMATOR).PARAMS
        self._params = NodeParameters(self, self.ESTIMATOR, (*NODE_PARAMS, *est_specs))
        p = self._params.declare()
        if not p["fixed_frame"].strip("/ "):
            raise ValueError("fixed_frame must not be empty")
        self.mag_file = self._load_mag_file(p)
        self._values = p
        self._est_names = {s.name for s in est_specs}
        self.stream = self._new_stream(self.mag_file.prior)
        self.add_pre_set_parameters_callback(self._params.coerce_sets)
        self.add_on_set_parameters_callback(self._on_set_parameters)

        self._last_warn: dict[str, float] = {}
        self._acc_in_g = False  # the gate's g-units verdict last logged
        self.outputs = Outputs(self, self.ATTITUDE_TOPIC, self.IMU_TOPIC, p, self._warn_throttled)
        qos = input_qos(p["input_qos"], int(p["input_depth"]))
        self._imu_sub = self.create_subscription(Imu, INPUT_TOPIC, self._on_imu_queue, qos)
        self._mag = mg.MagPairing()
        self.stream.field_monitor.pairing = self._mag  # (its stale and out-of-order counts)
        self._mag_state = ""  # the field state last logged
        uses_mag = mg.UseMag.parse(p["use_mag"]) is not mg.UseMag.FALSE and self.stream.estimator.USES_MAG
        self._mag_sub = self.create_subscription(MagneticField, MAG_TOPIC, self._on_mag, qos) if uses_mag else None
        self.create_service(Trigger, "~/reset", self._on_reset)
        self.create_service(Trigger, "~/restart", self._on_restart)
        if self.stream.estimator.USES_MAG:
            for name, force in ((SAVE_SERVICE, False), (SAVE_FORCE_SERVICE, True)):
                self.create_service(Trigger, name, functools.partial(self._on_save_mag_calibration, force=force))
        self.diag = Diagnostics(self, self.stream, self.ESTIMATOR, INPUT_TOPIC, MAG_TOPIC,
                                float(p["diagnostics_period"]))
        self.diag.mag_file = self.mag_file
        self.diag.world = self.outputs.world
        self._log_start(p, uses_mag, params_files or [], notes or [])

    def _new_stream(self, mag_prior: MagCalPrior | None) -> st.EstimatorStream:
        """The estimator behind its gate as built at start, from the current parameters; its online magnetometer
        calibration starts at ``mag_prior`` (None: the ``mag_hard_iron`` / ``mag_soft_iron`` parameters)."""
        p = self._values
        return st.EstimatorStream(create(self.ESTIMATOR, **{k: p[k] for k in self._est_names}),
                                  gt.GateConfig(**{s.name: p[s.name] for s in gt.GATE_PARAMS}),
                                  mg.MagConfig(**{s.name: p[s.name] for s in mg.MAG_PARAMS}), mag_prior=mag_prior)

    def _load_mag_file(self, p: dict[str, Any]) -> CalibrationFile:
        """:func:`~riann_ros.nodes.mag_calibration.start_file`; the parameters set to the values it leaves (before the
        run-time callbacks exist: a start-up value, not a change); the node logs the outcome."""
        f, refused = start_file(p)
        self._params.log += refused
        if f.loaded is not None or refused:
            self.set_parameters([Parameter(k, value=list(p[k])) for k in ("mag_hard_iron", "mag_soft_iron")])
        return f

    # -- run-time parameters ----------------------------------------------------------------------
    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        try:
            changes = check_changes(collect_changes(params, self._params.specs))
            values = {**self._values, **changes}
            new_gate = gt.GateConfig(**{s.name: values[s.name] for s in gt.GATE_PARAMS})
            new_mag = mg.MagConfig(**{s.name: values[s.name] for s in mg.MAG_PARAMS})
            est_changes = {k: v for k, v in changes.items() if k in self._est_names}
            if est_changes:
                self.stream.estimator.set_params(**est_changes)
        except (ValueError, TypeError) as e:
            self.get_logger().warning(f"parameters not changed: {e}")
            return SetParametersResult(successful=False, reason=str(e))
        self._values = values
        self.stream.gate.config = new_gate
        # a new mag_hard_iron / mag_soft_iron restarts the online calibration from them; else it goes on
        moved = {"mag_hard_iron", "mag_soft_iron"} & set(changes)
        self.stream.configure_mag(new_mag, None if moved else self.stream.mag_prior)
        self.outputs.configure(values)
        self.get_logger().info("parameters changed: " + ", ".join(f"{k}={v}" for k, v in changes.items()))
        return SetParametersResult(successful=True)

    # -- data path ------------------------------------------------------------------------------
    def _on_imu_queue(self, msg: Imu) -> None:
        """The executor hands over one IMU message; the ones already queued behind it (up to :data:`DRAIN_MAX`) are
        taken here too, in order, each after the field readings queued so far (so that a reading that arrived
        before an IMU message is paired as if each message had its own callback). A burst then costs the
        executor's wake-up once, not once per message."""
        self._take_mag()
        self._on_imu(msg)
        take = self._imu_sub.handle.take_message
        for _ in range(DRAIN_MAX):
            try:
                taken = take(Imu, False)
            except Exception:  # the subscription is gone (shutting down)
                return
            if taken is None:
                return
            self._take_mag()
            self._on_imu(taken[0])

    def _take_mag(self) -> None:
        """The field readings already queued, handed to the pairing."""
        sub = self._mag_sub
        if sub is None:
            return
        for _ in range(DRAIN_MAX):
            try:
                taken = sub.handle.take_message(MagneticField, False)
            except Exception:
                return
            if taken is None:
                return
            self._on_mag(taken[0])

    def _on_imu(self, msg: Imu) -> None:
        t0 = time.perf_counter_ns()
        stamp = msg.header.stamp
        stamp_ns = stamps.to_ns(stamp)
        la, av = msg.linear_acceleration, msg.angular_velocity
        receive_ns = self.get_clock().now().nanoseconds if stamp_ns == 0 else None
        diag = self.diag
        diag.inputs += 1
        if stamp_ns == 0:
            diag.zero_stamped += 1
        t1 = time.perf_counter_ns()
        field = self._mag.at(stamp_ns, self.stream.mag.config.timeout_ns)[0] if self._mag.received else None
        q, r = self.stream.process(stamp_ns, (la.x, la.y, la.z), (av.x, av.y, av.z), receive_ns, field)
        diag.est_us.append((time.perf_counter_ns() - t1) * 1e-3)
        if self._mag_state != self.stream.mag.state:
            self._log_mag_state()
        self._log_monitors()
        self._log_gate_result(r)
        if q is None:
            diag.rejected[r.reason or "?"] += 1
            self._warn_throttled(r.reason or "?", f"sample rejected ({r.reason}) at stamp {r.stamp_ns * 1e-9:.6f} s")
            return
        if r.reset is None and diag.rate.add(r.dt):
            self._check_rate()
        if stamp_ns == 0:  # publish with the receive time we used
            stamps.set_ns(stamp, r.stamp_ns)
        diag.frame_id = msg.header.frame_id
        self.outputs.publish(msg, (float(q[0]), float(q[1]), float(q[2]), float(q[3])),
                             self.stream.estimator.heading_observed(), self.stream.sigma)
        diag.proc_us.append((time.perf_counter_ns() - t0) * 1e-3)

    def _on_mag(self, msg: MagneticField) -> None:
        f = msg.magnetic_field
        self._mag.push(stamps.to_ns(msg.header.stamp), (f.x, f.y, f.z))
        self.diag.mag_received = self._mag.received

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        self.stream.reset()
        self._mag.clear()
        self.get_logger().info("reset requested: estimator state cleared")
        response.success = True
        response.message = f"{self.ESTIMATOR} estimator reset; re-initialising from the next sample"
        return response

    def _on_restart(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        """The estimator built anew, as at start with the current parameters: unlike ``~/reset`` this also forgets
        what belongs to the robot (the online magnetometer calibration, which starts again where it started, from
        ``mag_calibration_file`` as read at start or from ``mag_hard_iron`` / ``mag_soft_iron`` set since; the
        magnetometer's latency fit; the gate's counts)."""
        self.stream = self.diag.stream = self._new_stream(self.stream.mag_prior)
        self._mag.clear()
        self.stream.field_monitor.pairing = self._mag
        self._mag_state, self._acc_in_g = "", False
        self.get_logger().info("restart requested: estimator built anew, as at start (calibration included)")
        response.success = True
        response.message = (f"{self.ESTIMATOR} estimator built anew with the current parameters, its magnetometer "
                            "calibration as at start; initialising from the next sample")
        return response

    def _on_save_mag_calibration(self, request: Trigger.Request, response: Trigger.Response,
                                 force: bool) -> Trigger.Response:
        response.success, response.message = self.mag_file.save(self.stream.mag_calibration(), force)
        text = f"{SAVE_FORCE_SERVICE if force else SAVE_SERVICE}: {response.message}"
        if response.success:  # (one severity per call site: rclpy refuses a call site that changes it)
            self.get_logger().info(text)
        else:
            self.get_logger().warning(text)
        return response


def help_text(node_cls: type[EstimatorNode]) -> str:
    """``--help`` of a node executable: its topics and every parameter it declares (:mod:`riann_ros.nodes.usage`)."""
    est = estimator_class(node_cls.ESTIMATOR)
    topics = [("in", INPUT_TOPIC, "sensor_msgs/Imu: m/s², rad/s, sensor frame (REP-145)")]
    if est.USES_MAG:
        topics.append(("in", MAG_TOPIC, "sensor_msgs/MagneticField: tesla, optional (use_mag)"))
    topics += [
        ("out", node_cls.ATTITUDE_TOPIC, "geometry_msgs/QuaternionStamped: sensor → world_frame, in fixed_frame"),
        ("out", node_cls.IMU_TOPIC, "sensor_msgs/Imu: the input with orientation and its covariance"),
        ("out", rpy_topic(node_cls.ATTITUDE_TOPIC), "geometry_msgs/Vector3Stamped: roll, pitch, yaw, ° (publish_rpy)"),
        ("out", "/tf", "tf2_msgs/TFMessage: fixed_frame → sensor frame (publish_tf)"),
        ("out", "/diagnostics", "diagnostic_msgs/DiagnosticArray: rates, rejections, warnings"),
        ("srv", "~/reset", "std_srvs/Trigger: clear the estimator state (keeps the robot's magnetometer calibration)"),
        ("srv", "~/restart", "std_srvs/Trigger: build the estimator anew, as at start (calibration included)"),
    ]
    if est.USES_MAG:
        topics.append(("srv", SAVE_SERVICE, "std_srvs/Trigger: write the magnetometer calibration to "
                       "mag_calibration_file, unless that would downgrade the file's"))
        topics.append(("srv", SAVE_FORCE_SERVICE, "std_srvs/Trigger: write it even over a more certain one"))
    doc = sys.modules[node_cls.__module__].__doc__ or node_cls.NODE_NAME
    return usage.usage(node_cls.NODE_NAME, doc.strip().splitlines()[0], topics, NODE_PARAMS, node_cls.ESTIMATOR,
                       est.PARAMS)


def run(node_cls: type[EstimatorNode], args: list[str] | None = None) -> int:
    """Entry point shared by all node executables: ``-h``/``--help`` prints the help and returns; else init, spin
    until Ctrl-C / shutdown, clean up."""
    argv = list(args if args is not None else sys.argv)
    if usage.help_requested(argv):
        print(help_text(node_cls), end="")
        return 0
    fixed, notes = ros_args.normalise(argv)
    temp_files = [f for f in ros_args.params_files(fixed) if f not in ros_args.params_files(argv)]
    node = None
    try:
        rclpy.init(args=fixed)
    except Exception as e:  # rcl refuses the arguments (a parameter file or rule it cannot parse)
        print(f"{node_cls.NODE_NAME}: error: {e}", file=sys.stderr)
        return 1
    try:
        node = node_cls(params_files=ros_args.params_files(argv), notes=notes)
        # what start-up made (rclpy, numpy, ONNX Runtime, the node) stays out of the garbage collector's full
        # passes, which otherwise stalled the 1 kHz data path for 28-89 ms (BENCHMARKS.md, node profile)
        gc.collect()
        gc.freeze()
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
        for f in temp_files:
            os.unlink(f)
    return 0
