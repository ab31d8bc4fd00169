"""The nodes' ``/diagnostics`` and the stamp-rate check behind ``nominal_rate``'s warning."""

from __future__ import annotations

import math
import statistics
import time
from collections import Counter

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node

from riann_ros import gate as gt
from riann_ros import stream as st
from riann_ros.magcal import input as mg
from riann_ros.monitors import Level
from riann_ros.nodes.mag_calibration import CalibrationFile, status_values

RATE_CHECK_SAMPLES = 100  # accepted samples (restarts excluded) whose median dt gives the measured stamp rate
RATE_TOLERANCE = 0.10  # relative difference between measured and nominal rate that is warned about


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


def _stat(values: list[float], f: str) -> str:
    if not values:
        return "nan"
    a = np.asarray(values)
    return f"{np.percentile(a, 99) if f == 'p99' else getattr(a, f)():.1f}"


class Diagnostics:
    """One node's ``/diagnostics`` status: counts what happens in each period and publishes it."""

    def __init__(self, node: Node, stream: st.EstimatorStream, estimator: str, input_topic: str, mag_topic: str,
                 period_s: float) -> None:
        self.node = node
        self.stream = stream
        self.estimator = estimator
        self.input_topic = node.resolve_topic_name(input_topic)
        self.mag_topic = node.resolve_topic_name(mag_topic)
        self.rate = StampRateCheck()
        self.frame_id = ""
        self.world = ""
        self.mag_received = 0
        self._pub = node.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._start = time.monotonic()
        self.inputs = 0
        self.zero_stamped = 0  # messages of the period with a zero header stamp (stamped on receipt)
        self.rejected: Counter[str] = Counter()
        self.proc_us: list[float] = []
        self.est_us: list[float] = []
        self.config_warnings: list[str] = []  # the start-up warnings on parameters (values written but not applied)
        self._use_mag_warned = False  # use_mag true without a field: logged once
        self.mag_file = CalibrationFile("")  # the node's mag_calibration_file
        node.create_timer(period_s, self.publish)

    def level(self) -> tuple[bytes, str]:
        """(level, message) of this period. ERROR: input arrived but no estimate was published (every message
        rejected), or a monitor says the estimate is not to be trusted (:mod:`riann_ros.monitors`). WARN, for as
        long as it holds: a monitor's warning (input loss, the magnetometer's readings or calibration), no input,
        rejections, an accelerometer in g, zero stamps, a nominal_rate far from the stamp rate, use_mag true without
        a field, parameters not applied. The message names each with what to do."""
        problems = []
        if self.inputs == 0:
            problems.append("no input on " + self.input_topic)
        n_rejected = sum(self.rejected.values())
        if n_rejected:
            problems.append("samples rejected: " + ", ".join(f"{k}={v}" for k, v in self.rejected.items()))
        gate = self.stream.gate
        if gate.acc_in_g:
            problems.append(f"accelerometer in g? median |acc| {gate.acc_median:.2f} over the first "
                            f"{gt.G_CHECK_SAMPLES} samples, REP-145 wants m/s² (9.81 at rest): estimates are wrong, "
                            f"scale the driver's output by {gt.GRAVITY}")
        if self.zero_stamped:
            problems.append(f"{self.zero_stamped} messages with zero header stamps, stamped on receipt: dt includes "
                            "transport jitter (fix the driver's stamping)")
        nominal = gate.config.nominal_rate
        if self.rate.mismatch(nominal) is not None:
            problems.append(f"nominal_rate {nominal:.1f} Hz differs from the measured stamp rate "
                            f"{self.rate.measured_hz:.1f} Hz: set nominal_rate")
        mag = self.stream.mag
        if mag.config.use_mag is mg.UseMag.TRUE and self.stream.estimator.USES_MAG and mag.state != mg.FIELD_USED:
            problems.append(f"use_mag is true but {mag.state[4:]} on {self.mag_topic}")
        if self.config_warnings:
            problems.append(f"{len(self.config_warnings)} parameter warning(s) at start-up, values not applied "
                            f"(see the log): {self.config_warnings[0][:100]}")
        verdicts = [v for v in self.stream.monitors.verdicts() if v.level > Level.OK]
        problems += [f"{v.name}: {v.message}" for v in verdicts]
        none_published = n_rejected >= self.inputs > 0
        if none_published or any(v.level == Level.ERROR for v in verdicts):
            head = [f"no estimate published: all {self.inputs} messages rejected"] if none_published else []
            return DiagnosticStatus.ERROR, "; ".join([*head, *problems])
        if problems:
            return DiagnosticStatus.WARN, "; ".join(problems)
        return DiagnosticStatus.OK, "ok"

    def values(self, period: float) -> dict[str, str]:
        gate = self.stream.gate
        est = self.stream.estimator
        dts = gate.pop_dt_stats()
        measured = self.rate.measured_hz
        values = {
            "input rate (Hz)": f"{self.inputs / period:.2f}",
            "stamp rate measured (Hz)": f"{measured:.2f}" if measured is not None else "nan",
            "nominal_rate (Hz)": f"{gate.config.nominal_rate:.2f}",
            **{f"dt {k} (ms)": f"{dts.get(k, math.nan) * 1e3:.3f}" for k in ("min", "mean", "max", "std")},
            "samples accepted (total)": str(gate.accepted),
            "accelerometer median |acc| at (re)start (m/s2)": (f"{gate.acc_median:.2f}" if gate.acc_median is not None
                                                               else "nan"),
            "zero stamps in period": str(self.zero_stamped),
            "inference time mean (us)": _stat(self.est_us, "mean"),
            "inference time max (us)": _stat(self.est_us, "max"),
            "processing time mean (us)": _stat(self.proc_us, "mean"),
            "processing time p99 (us)": _stat(self.proc_us, "p99"),
            "processing time max (us)": _stat(self.proc_us, "max"),
            "world frame": self.world,
            "magnetometer": self.stream.field_monitor.state() if est.USES_MAG else "not used by this estimator",
            "field readings received (total)": str(self.mag_received),
            "heading": "magnetic (9D)" if est.heading_observed() else "gyro only",
        }
        values.update(est.diagnostics())
        values.update(self._monitor_values())
        if est.USES_MAG and self._field_expected():
            values.update(status_values(self.stream.mag_cal_status(), self.mag_file))
        for reason in gt.REJECT_REASONS:
            values[f"rejected {reason} (total)"] = str(gate.rejected[reason])
        for cause in (gt.GAP, gt.CLOCK_JUMP):
            values[f"restarts {cause} (total)"] = str(gate.resets[cause])
        return values

    def _field_expected(self) -> bool:
        """A field is in the picture: use_mag is not false and a reading came, or use_mag is true (a 6D node shows
        no calibration values)."""
        use = self.stream.mag.config.use_mag
        return use is mg.UseMag.TRUE or (use is mg.UseMag.AUTO and self.mag_received > 0)

    def _monitor_values(self) -> dict[str, str]:
        """Each monitor's level and what it measured."""
        s = self.stream
        out = {f"monitor {v.name}": v.level.name for v in s.monitors.verdicts()}
        ratio = s.gyro_units.ratio
        out["gyro / accelerometer tilt ratio"] = "nan" if ratio is None else f"{ratio:.3f}"
        out["input lost (%, last 10 s)"] = f"{100.0 * s.loss.share:.1f}"
        if s.estimator.USES_MAG and self._field_expected():
            out.update({f"field readings {k} (total)": str(v) for k, v in s.field_monitor.counts().items()})
        out.update({f"monitor {k} trips (total)": str(n) for k, n in s.monitors.trips.items()})
        return out

    def _warn_use_mag(self) -> None:
        """use_mag true and no field used in the first period: one WARN in the log (and in every WARN status)."""
        mag = self.stream.mag
        if (self._use_mag_warned or mag.config.use_mag is not mg.UseMag.TRUE or not self.stream.estimator.USES_MAG
                or mag.state == mg.FIELD_USED):
            return
        self._use_mag_warned = True
        self.node.get_logger().warning(f"use_mag is true but {mag.state[4:]} on {self.mag_topic}: the heading "
                                       "follows the gyro (check the magnetometer's topic and driver, or set use_mag "
                                       "auto)")

    def publish(self) -> None:
        self._warn_use_mag()
        now = time.monotonic()
        status = DiagnosticStatus()
        status.name = f"{self.node.get_name()}: {self.estimator} attitude estimator"
        status.hardware_id = self.frame_id
        status.level, status.message = self.level()
        status.values = [KeyValue(key=k, value=v) for k, v in self.values(max(now - self._start, 1e-9)).items()]
        arr = DiagnosticArray()
        arr.header.stamp = self.node.get_clock().now().to_msg()
        arr.status = [status]
        self._pub.publish(arr)
        self._start = now
        self.inputs = 0
        self.zero_stamped = 0
        self.rejected.clear()
        self.proc_us = []
        self.est_us = []
