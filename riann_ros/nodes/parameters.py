"""The nodes' ROS parameters: their specs, their declaration, the types users write, imu_tools' names.

Every parameter is a :class:`~riann_ros.params.ParamSpec` (the node's own below, the input gate's
:data:`riann_ros.gate.GATE_PARAMS`, the magnetometer's :data:`riann_ros.magcal.input.MAG_PARAMS`, the estimator's
``PARAMS``). :class:`NodeParameters` declares them on the node:

* **types** — YAML and the command line type a value by its spelling (``200`` is an integer, ``false`` a
  bool), so each start-up value is read through a dynamically typed declaration, converted and checked by
  :meth:`ParamSpec.coerce`, and the parameter is then declared in its own type holding that value (with
  its description and range for ``ros2 param describe``). Run-time sets are converted the same way before
  rclpy checks the type (:meth:`NodeParameters.coerce_sets`).
* **imu_tools' names** (:mod:`riann_ros.nodes.imu_tools`) are translated into ours, or refused with the reason.
* **unknown names** are warned about, each with the closest known name.
"""

from __future__ import annotations

from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.node import Node
from rclpy.parameter import Parameter

from riann_ros import frames
from riann_ros import gate as gt
from riann_ros.defaults import INCLINATION_SD_DEG, MAG_HEADING_SD_DEG, YAW_FREE_SD_DEG
from riann_ros.estimators import REGISTRY, estimator_class
from riann_ros.magcal import input as mg
from riann_ros.nodes import imu_tools
from riann_ros.nodes.mag_calibration import MAG_CALIBRATION_FILE
from riann_ros.params import ParamSpec

QOS_CHOICES = ("sensor_data", "reliable", "best_effort")

#: Parameters of the node itself (the gate's come from :data:`riann_ros.gate.GATE_PARAMS`, the
#: estimator's from its ``PARAMS``); those with ``runtime=False`` only take effect at start-up.
NODE_ONLY_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec("input_qos", "sensor_data", "Input QoS: sensor_data (best effort, connects to reliable and "
              "best-effort drivers), best_effort, or reliable.", choices=QOS_CHOICES),
    ParamSpec("input_depth", 1000, "Input queue depth (keep last): a burst larger than this loses its oldest "
              "messages in DDS before the node sees them.", min=1, max=100000),
    ParamSpec("output_depth", 1000, "Output queue depth (keep last, reliable): outputs not yet acknowledged by a "
              "slow subscriber are dropped once more than this many are queued.", min=1, max=100000),
    ParamSpec("orientation_covariance", "model", "Orientation covariance of imu/data: 'model' = the estimator's "
              "per-sample standard deviations (RIANN: its uncertainty model; Madgwick, Mahony, VQF: documented "
              "constants, the heading's widened by the calibration's doubt and by the filter's disagreement with "
              "its own field), 'constant' = roll_pitch_stddev_deg, yaw_stddev_deg and mag_yaw_stddev_deg.",
              choices=("model", "constant"), runtime=True),
    ParamSpec("roll_pitch_stddev_deg", INCLINATION_SD_DEG, "deg; with orientation_covariance: constant, the standard "
              "deviation written to the roll and pitch entries of the orientation covariance of imu/data.", min=0.0,
              max=180.0, runtime=True),
    ParamSpec("yaw_stddev_deg", YAW_FREE_SD_DEG, "deg; standard deviation written to the yaw entry of the orientation "
              "covariance while the heading is not tied to a magnetometer (it is unobservable: gyro drift only).",
              min=0.0, max=1.0e6, runtime=True),
    ParamSpec("mag_yaw_stddev_deg", MAG_HEADING_SD_DEG, "deg; standard deviation of the yaw entry while the heading "
              "is corrected by an undisturbed magnetometer field (9D).", min=0.0, max=1.0e6, runtime=True),
    ParamSpec("diagnostics_period", 1.0, "s; period of /diagnostics messages.", min=0.05, max=3600.0),
    ParamSpec("world_frame", frames.ENU, "World frame of the published orientation (imu/attitude, imu/data, imu/rpy, "
              "TF): enu (x east, y north, z up; REP-103), ned (x north, y east, z down) or nwu (x north, y west, "
              "z up); the physical change of axes from ENU (docs/node.md, Frames).", choices=frames.WORLD_FRAMES),
    ParamSpec("yaw_offset_deg", 0.0, "deg; the published orientation is turned by this angle about the world z axis "
              "(q = Rz(yaw_offset_deg) q_world), e.g. a mounting offset of the heading.", min=-360.0, max=360.0,
              runtime=True),
    ParamSpec("fixed_frame", "odom", "frame_id of imu/attitude and imu/rpy (a QuaternionStamped is expressed in its "
              "header frame: the world frame, not the sensor's) and parent frame of the TF; imu/data keeps the "
              "input's sensor frame."),
    ParamSpec("publish_tf", False, "Broadcast fixed_frame -> the input's frame_id on /tf (rotation only, zero "
              "translation; for visualising a stand-alone IMU). Needs tf2_msgs (a system ROS 2)."),
    ParamSpec("reverse_tf", False, "With publish_tf: broadcast the inverse, the input's frame_id -> fixed_frame "
              "(as imu_tools' reverse_tf), for a tree where the sensor frame already has a parent."),
    ParamSpec("publish_rpy", False, "Publish roll, pitch, yaw in degrees (ZYX, in world_frame) as "
              "geometry_msgs/Vector3Stamped on imu/rpy (x = roll, y = pitch, z = yaw), for plotting."),
    ParamSpec("remove_gravity_vector", False, "Subtract gravity (9.80665 m/s² along the estimated vertical) from "
              "linear_acceleration in imu/data, as imu_tools' remove_gravity_vector.", runtime=True),
)
NODE_PARAMS: tuple[ParamSpec, ...] = (*gt.GATE_PARAMS, *mg.MAG_PARAMS, MAG_CALIBRATION_FILE, *NODE_ONLY_PARAMS)

_ROS_TYPES = {bool: Parameter.Type.BOOL, int: Parameter.Type.INTEGER, float: Parameter.Type.DOUBLE,
              str: Parameter.Type.STRING, tuple: Parameter.Type.DOUBLE_ARRAY}


def descriptor(spec: ParamSpec) -> ParameterDescriptor:
    """The ROS descriptor of a spec: description, read-only unless it may change at run time, its range."""
    d = ParameterDescriptor(description=spec.description, read_only=not spec.runtime)
    if spec.min is not None and spec.max is not None and not isinstance(spec.default, bool | tuple):
        if isinstance(spec.default, int):
            d.integer_range = [IntegerRange(from_value=int(spec.min), to_value=int(spec.max), step=1)]
        elif isinstance(spec.default, float):
            lo, hi = float(spec.min), float(spec.max)
            d.floating_point_range = [FloatingPointRange(from_value=lo, to_value=hi, step=0.0)]
    return d


def ros_value(value: Any) -> Any:
    """A spec value as rclpy stores it (tuples as lists)."""
    return list(value) if isinstance(value, tuple) else value


def owners() -> dict[str, list[str]]:
    """Estimator parameter name -> the nodes that have it."""
    out: dict[str, list[str]] = {}
    for name in REGISTRY:
        for p in estimator_class(name).PARAMS:
            out.setdefault(p.name, []).append(f"{name}_node")
    return out


class NodeParameters:
    """Declares ``specs`` on ``node`` (running ``estimator``); :attr:`log` holds the start-up messages
    ((level, text), level ``info`` or ``warning``) for the node to log."""

    def __init__(self, node: Node, estimator: str, specs: tuple[ParamSpec, ...]) -> None:
        self.node = node
        self.estimator = estimator
        self.specs = {s.name: s for s in specs}
        self.log: list[tuple[str, str]] = []
        self._handled: set[str] = set()
        self._origins: dict[str, list[str]] = {}  # our parameter -> the imu_tools names that set it

    # -- start-up ---------------------------------------------------------------------------------------
    def declare(self) -> dict[str, Any]:
        """Declare every parameter; return the start-up values (converted and checked). A value that cannot be
        converted raises ``ValueError`` naming the parameter (the node exits with it)."""
        # rclpy keeps the command line's and parameter files' values for this node here; it has no public
        # accessor (Node(automatically_declare_parameters_from_overrides=True) would declare them typed as
        # written, and fail on an empty list).
        overrides: dict[str, Parameter] = dict(getattr(self.node, "_parameter_overrides", {}))
        from_aliases = self._translate({k: p.value for k, p in overrides.items() if k not in self.specs}, overrides)
        values = {}
        for name, spec in self.specs.items():
            raw = self.node.declare_parameter(name, ros_value(spec.default),
                                              ParameterDescriptor(dynamic_typing=True)).value
            origin = ""
            if name not in overrides and name in from_aliases:
                raw = from_aliases[name]
                origin = f" (from imu_tools' {', '.join(self._origins[name])})"
            self.node.undeclare_parameter(name)
            try:
                values[name] = spec.coerce(raw)
            except ValueError as e:
                raise ValueError(f"{e}{origin}") from None
            self.node.declare_parameter(name, ros_value(values[name]), descriptor(spec), ignore_override=True)
        self._report_unknown(overrides)
        return values

    def _translate(self, candidates: dict[str, Any], overrides: dict[str, Parameter]) -> dict[str, Any]:
        """imu_tools names among ``candidates`` -> our parameters' raw values (array elements merged)."""
        out: dict[str, Any] = {}
        for name, value in sorted(candidates.items()):
            t = imu_tools.translate(name, value, self.estimator)
            if t is None:
                continue
            self._handled.add(name)
            if t.refused is not None:
                self.log.append(("warning", f"parameter '{name}' ({t.source}) = {value!r} refused: {t.refused}"))
                continue
            clash = sorted({target.split("[")[0] for target in t.values} & set(overrides))
            if clash:
                self.log.append(("warning", f"parameter '{name}' ({t.source}) ignored: {', '.join(clash)} set too"))
                continue
            for target, v in t.values.items():
                base = target.split("[")[0]
                if base not in self.specs:
                    continue
                if "[" in target:
                    arr = list(out.get(base, self.specs[base].default))
                    arr[int(target.split("[")[1].rstrip("]"))] = v
                    v = arr
                out[base] = v
                self._origins.setdefault(base, []).append(f"'{name}'")
            targets = ", ".join(f"{k} = {v:g}" if isinstance(v, float) else f"{k} = {v}" for k, v in t.values.items())
            level = "warning" if "WARNING" in t.note else "info"
            self.log.append((level, f"parameter '{name}' ({t.source}) = {value!r}: "
                             + (f"{targets} ({t.note})" if targets else t.note)))
        return out

    def _report_unknown(self, overrides: dict[str, Parameter]) -> None:
        unknown = [n for n in sorted(overrides)  # not ours nor rclpy's own (use_sim_time, ...)
                   if not self.node.has_parameter(n) and n not in self._handled]
        if unknown:
            known = sorted({*self.specs, *imu_tools.ALIASES})
            own = {k: v for k, v in owners().items() if k not in self.specs}
            self.log += [("warning", imu_tools.unknown_text(name, known, own)) for name in unknown]

    # -- run time ---------------------------------------------------------------------------------------
    def coerce_sets(self, params: list[Parameter]) -> list[Parameter]:
        """Pre-set callback: a value written as another type (``1`` for a float, ``"true"`` for a bool) becomes the
        parameter's own type; a value that does not convert is left for rclpy to refuse."""
        out = []
        for prm in params:
            spec = self.specs.get(prm.name)
            if spec is not None and prm.type_ != _ROS_TYPES[type(spec.default)]:
                try:
                    prm = Parameter(prm.name, _ROS_TYPES[type(spec.default)], ros_value(spec.coerce(prm.value)))
                except (ValueError, TypeError):
                    pass
            out.append(prm)
        return out


def collect_changes(params: list[Parameter], specs: dict[str, ParamSpec]) -> dict[str, Any]:
    """Run-time set: ``{name: value}`` converted and checked by the specs; ``ValueError`` names the first
    parameter refused (read-only at run time, a wrong value)."""
    out = {}
    for prm in params:
        spec = specs.get(prm.name)
        if spec is None:
            continue
        if not spec.runtime:
            raise ValueError(f"{prm.name} is read-only at run time")
        out[prm.name] = spec.coerce(prm.value)
    return out
