"""The magnetometer's monitors: its readings (plausibility, timeliness, order) and the calibration the field gets
(ROS-free).

:class:`FieldMonitor` counts the readings the stream could not use, by cause: not finite, a norm outside the
plausible 1 µT–1 mT (a dead or saturated sensor, a field in the wrong unit), older than ``mag_timeout`` when an IMU
sample came (a slow or stalled magnetometer), stamped before the previous reading (its clock went back; the node's
pairing starts over). The stale and out-of-order counts come from the node's pairing
(:class:`~riann_ros.magcal.input.MagPairing`); offline the evaluator pairs the bag before (its NaN rows are no
reading). It WARNs while readings arrive but the last sample got none it could use, naming the cause; the heading then
follows the gyro (the estimate's σ says so: the heading's σ grows without a field).

:class:`CalibrationMonitor` reports what the online calibration's gyro-aided test says of the configured (or saved)
calibration: with ``mag_calibration`` off (the test then runs as a monitor: the field keeps the configured
calibration, the user's choice) a rejected calibration is a WARN, and the heading's σ includes the heading
difference to the calibration the windows point to (the front end's, :mod:`riann_ros.magcal.frontend`); with it on,
the online estimate takes over and the verdict stays OK.
"""

from __future__ import annotations

from riann_ros.magcal import input as mg
from riann_ros.magcal.frontend import MagFrontEnd
from riann_ros.magcal.records import UT
from riann_ros.monitors.base import Level, Verdict


class FieldMonitor:
    """The magnetometer's readings (module docstring)."""

    NAME = "magnetometer readings"

    def __init__(self, mag: mg.MagInput, pairing: mg.MagPairing | None = None) -> None:
        self.mag = mag
        self.pairing = pairing  # the node's (stale and out-of-order counts); None offline

    def counts(self) -> dict[str, int]:
        """The readings not used so far, by cause."""
        p = self.pairing
        return {"not finite": self.mag.non_finite, "implausible norm": self.mag.implausible,
                "stale": p.stale if p is not None else 0, "out of order": p.out_of_order if p is not None else 0}

    def state(self) -> str:
        """The field's state of the last sample (:mod:`riann_ros.magcal.input`), saying so where readings came but
        none could be paired or used (the input alone calls that "no field received")."""
        state = self.mag.state
        received = self.pairing.received if self.pairing is not None else 0
        if state == mg.FIELD_NONE and received:
            return f"6D: {received} readings received, none used"
        return state

    def verdict(self) -> Verdict:
        state = self.state()
        if state not in (mg.FIELD_BAD, mg.FIELD_NONFINITE, mg.FIELD_STALE) and not state.endswith("none used"):
            return Verdict(self.NAME)
        n = {k: v for k, v in self.counts().items() if v}
        counted = ", ".join(f"{v} {k}" for k, v in n.items()) or "none counted"
        fix = {mg.FIELD_BAD: "check the magnetometer's unit (sensor_msgs/MagneticField is tesla) and that it is not "
                             "saturated by a magnet",
               mg.FIELD_NONFINITE: "the driver publishes NaN or inf: check the sensor"}.get(
                   state, "the readings come slower or later than mag_timeout, or are stamped out of order: check the "
                          "magnetometer's rate and stamps (they must share the IMU's clock), or raise mag_timeout")
        return Verdict(self.NAME, Level.WARN, f"{state[4:]} (readings not used: {counted}); the heading follows the "
                                              f"gyro: {fix}")


class CalibrationMonitor:
    """What the gyro-aided test says of the configured calibration (module docstring)."""

    NAME = "magnetometer calibration"

    def __init__(self, front: MagFrontEnd) -> None:
        self.front = front

    def verdict(self) -> Verdict:
        cal = self.front.cal
        if cal is None or not self.front.monitoring or cal.test.holds:
            return Verdict(self.NAME)
        est = self.front.estimate_hard_iron_t()
        text = ", ".join(f"{v / UT:+.1f}" for v in est)
        return Verdict(self.NAME, Level.WARN,
                       "the gyro-aided test rejects the configured magnetometer calibration (mag_calibration is "
                       f"false; the windows point to a hard iron of ({text}) µT): the heading may be off, its σ says "
                       "by how much; set mag_calibration true, or recalibrate (riann-mag-calibrate)")


class LagMonitor:
    """A magnetometer whose readings come later than the latency fit can see (:mod:`riann_ros.magcal.lag`)."""

    NAME = "magnetometer lag"

    def __init__(self, front: MagFrontEnd) -> None:
        self.front = front

    def verdict(self) -> Verdict:
        late = self.front.late_s
        if late is None:
            return Verdict(self.NAME)
        return Verdict(self.NAME, Level.WARN,
                       f"the magnetometer's readings are about {1e3 * late:.0f} ms older than their stamps (the field "
                       "against the gyro): compensated by the gyro's rotation over that time; fix the driver's stamps "
                       "(a reading stamped when it was measured)")
