"""What the node base logs (:class:`NodeLog`, a part of :class:`~riann_ros.nodes.node_base.EstimatorNode`): its
start-up line and the warnings on its parameters, the switches between 9D and 6D, each monitor's trip and recovery,
the input gate's one-shot warnings and restarts, the stamp rate against ``nominal_rate``, and throttled per-reason
warnings. One line per event: what happened and what to do."""

from __future__ import annotations

import math
import time
from typing import Any, ClassVar

from rclpy.node import Node

from riann_ros import gate as gt
from riann_ros import stream as st
from riann_ros.magcal import input as mg
from riann_ros.monitors import Level
from riann_ros.nodes import ros_args
from riann_ros.nodes.diagnostics import Diagnostics
from riann_ros.nodes.mag_calibration import CalibrationFile
from riann_ros.nodes.outputs import Outputs
from riann_ros.nodes.parameters import NodeParameters

THROTTLE_S = 5.0  # at most one warning per rejection reason in this many seconds
INPUT_TOPIC = "imu/data_raw"
MAG_TOPIC = "imu/mag"


class NodeLog(Node):
    """The node's log lines (module docstring): the rclpy node the node base is, with what it logs; the node base
    sets the state below."""

    ESTIMATOR: ClassVar[str] = ""
    stream: st.EstimatorStream
    diag: Diagnostics
    outputs: Outputs
    mag_file: CalibrationFile
    _params: NodeParameters
    _last_warn: dict[str, float]
    _acc_in_g: bool  # the gate's g-units verdict last logged
    _mag_state: str  # the field state last logged

    def _log_start(self, p: dict[str, Any], uses_mag: bool, params_files: list[str], notes: list[str]) -> None:
        log = self.get_logger()
        mag_text = (f"; magnetometer on '{self.resolve_topic_name(MAG_TOPIC)}' (use_mag={p['use_mag']})"
                    if uses_mag else "; magnetometer not used")
        log.info(
            f"{self.ESTIMATOR} estimator on '{self.resolve_topic_name(INPUT_TOPIC)}' -> "
            + ", ".join(f"'{self.resolve_topic_name(t)}'" for t in self.outputs.topics)
            + f"; orientation in {self.outputs.world.upper()} (world_frame), imu/attitude in frame "
            f"'{self.outputs.fixed_frame}'" + mag_text
            + "; parameters: " + ", ".join(f"{k}={v}" for k, v in p.items())
        )
        for text in notes:
            log.info(f"arguments: {text}")
        warnings = []
        for level, text in [*self._params.log, *self.mag_file.log]:
            if level == "warning":  # (rclpy's logger wants one severity per call site)
                log.warning(text)
                warnings.append(text)
            else:
                log.info(text)
        fqn = self.get_fully_qualified_name()
        for path, key, names in ros_args.foreign_sections(params_files, fqn):
            text = (f"parameter file {path}: section '{key}' does not apply to this node ({fqn}); its parameters "
                    f"{', '.join(names)} are not used (key the section '/**' or '{self.get_name()}', or start the "
                    f"node under that name: --ros-args -r __node:={key.rsplit('/', 1)[-1]})")
            log.warning(text)
            warnings.append(text)
        self.diag.config_warnings = warnings  # WARN in /diagnostics too: values written but not applied

    def _log_mag_state(self) -> None:
        """Log the switches between 9D and 6D (auto: as they happen; the reason is in /diagnostics too)."""
        old, new = self._mag_state, self.stream.mag.state
        self._mag_state = new
        if new == mg.FIELD_NONE and old in ("", mg.FIELD_NONE):
            return  # no magnetometer so far: nothing to say (the start-up line names the topic)
        text = f"magnetometer: {new}" + ("" if new == mg.FIELD_USED else " (heading held by the gyro)")
        if new == mg.FIELD_USED or self.stream.mag.config.use_mag is mg.UseMag.AUTO:
            self.get_logger().info(text)
        else:
            self.get_logger().warning(text)

    def _log_monitors(self) -> None:
        """One log line per monitor verdict that changed level (a trip: WARN or ERROR with its cause and fix; a
        recovery: INFO)."""
        for v in self.stream.monitors.pop_changes():
            log = self.get_logger()
            if v.level == Level.ERROR:
                log.error(f"{v.name}: {v.message}")
            elif v.level == Level.WARN:
                log.warning(f"{v.name}: {v.message}")
            else:
                log.info(f"{v.name}: ok again")

    def _log_gate_result(self, r: gt.GateResult) -> None:
        for w in r.warnings:
            self.get_logger().warning(gt.WARNING_TEXT[w])
        if self._acc_in_g != self.stream.gate.acc_in_g:
            self._acc_in_g = not self._acc_in_g
            if not self._acc_in_g:  # (the warning itself came with r.warnings)
                self.get_logger().info(f"accelerometer: median |acc| {self.stream.gate.acc_median:.2f} m/s² after "
                                       "the (re)start, in m/s² as REP-145 wants")
        if r.reset in (gt.GAP, gt.CLOCK_JUMP):
            self.get_logger().info(f"{r.reset.replace('_', ' ')} at stamp {r.stamp_ns * 1e-9:.6f} s: estimator "
                                   "restarted, re-initialised from this sample")

    def _check_rate(self) -> None:
        nominal = self.stream.gate.config.nominal_rate
        if self.diag.rate.mismatch(nominal) is not None:
            self.get_logger().warning(self.diag.rate.text(nominal))

    def _warn_throttled(self, key: str, text: str) -> None:
        now = time.monotonic()
        if now - self._last_warn.get(key, -math.inf) >= THROTTLE_S:
            self._last_warn[key] = now
            self.get_logger().warning(text + " (throttled: one message per reason every 5 s; counts in /diagnostics)")
