"""The monitors of the input path on the installed node executables over real DDS (riann_ros.monitors): a gyro in
deg/s is an ERROR in /diagnostics within 5 s of tilting motion, with one log line and a covariance that says the
orientation is not to be trusted; a stream that loses 18 % of its messages is a WARN; a correct stream stays OK.
The same monitors in-process: what they count, and that a correct sensor never trips them (synthetic here, the 12
BROAD trials in test_monitors_broad)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from sensor_msgs.msg import Imu

from conftest import wait_for, wait_matched
from helpers_ros import imu_msg, publish_paced
from riann_ros import quaternion as quat
from riann_ros.constants import GRAVITY
from riann_ros.estimators import create
from riann_ros.monitors import UNTRUSTED_SD_RAD, Level
from riann_ros.monitors.input_loss import WARN_SHARE
from riann_ros.stream import EstimatorStream, GateConfig

T0 = 1_700_000_000 * 1_000_000_000
RATE = 200.0
DEG_S = math.degrees(1.0)  # a gyro in deg/s read as rad/s


def tilting(seconds: float = 10.0, rest: float = 1.0, turn_s: float = 0.3, hold_s: float = 0.3,
            angle_deg: float = 30.0, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A sensor at rest, then tilted back and forth by ``angle_deg`` about alternating horizontal axes, held still
    between the tilts (a robot arm, a legged robot stepping): stamps (ns), acc (m/s²), gyr (rad/s) with noise."""
    n = int(seconds * RATE)
    dt = 1.0 / RATE
    t = np.arange(n) * dt
    gyr = np.zeros((n, 3))
    phase = t - rest
    cycle = np.floor(phase / (turn_s + hold_s)).astype(int)
    within = phase - cycle * (turn_s + hold_s)
    moving = (phase >= 0.0) & (within < turn_s)
    axes = np.array([(1, 0, 0), (0, 1, 0), (-1, 0, 0), (0, -1, 0)], dtype=float)[cycle % 4]
    rate = math.radians(angle_deg) / turn_s * math.pi / 2 * np.sin(math.pi * within / turn_s)
    gyr[moving] = axes[moving] * rate[moving, None]
    q = np.empty((n, 4))
    q[0] = quat.IDENTITY
    for i in range(1, n):
        q[i] = quat.multiply(q[i - 1], quat.from_rotvec(gyr[i] * dt))
    acc = quat.rotate(quat.conjugate(quat.normalize(q)), np.tile([0.0, 0.0, GRAVITY], (n, 1)))
    rng = np.random.default_rng(seed)
    return (T0 + np.round(t * 1e9).astype(np.int64), acc + rng.normal(0.0, 0.02, acc.shape),
            gyr + rng.normal(0.0, 0.002, gyr.shape))


def first_untrusted_s(stamps, acc, gyr, name: str = "vqf") -> float | None:
    """s after the first sample at which the stream's monitors first say the estimate is not to be trusted."""
    s = EstimatorStream(create(name), GateConfig(nominal_rate=RATE))
    for i in range(len(stamps)):
        s.process(int(stamps[i]), acc[i], gyr[i])
        if s.monitors.untrusted:
            assert s.sigma is not None and np.all(s.sigma == UNTRUSTED_SD_RAD)
            return (stamps[i] - stamps[0]) * 1e-9
    return None


@pytest.mark.parametrize("scale, found", [(1.0, False), (DEG_S, True), (1.0 / GRAVITY, True), (1e-3 * DEG_S, False)])
def test_a_gyro_in_another_unit_is_found_within_seconds_of_tilting(scale, found):
    """deg/s read as rad/s and a rate divided by g are found within 3 s of tilting motion (five tilts); a right gyro
    never; a gyro read 1000 times too small is not one of the slips (its tilts scatter; none is claimed)."""
    stamps, acc, gyr = tilting()
    t = first_untrusted_s(stamps, acc, gyr * scale)
    if found:
        assert t is not None and t - 1.0 < 3.0  # (1 s of rest first)
    else:
        assert t is None


def test_a_correct_gyro_is_not_flagged_in_the_batch_path_either():
    """The evaluator's batch path runs the same monitors sample by sample: a deg/s gyro widens the σ of the samples
    after the slip is found, a right one none."""
    stamps, acc, gyr = tilting()
    for scale, any_untrusted in ((1.0, False), (DEG_S, True)):
        s = EstimatorStream(create("madgwick"), GateConfig(nominal_rate=RATE))
        s.process_batch(stamps, acc, gyr * scale)
        untrusted = np.all(s.batch_sigma == UNTRUSTED_SD_RAD, axis=1)
        assert bool(untrusted.any()) == any_untrusted
        if any_untrusted:
            k = int(np.argmax(untrusted))
            assert untrusted[k:].all() and (stamps[k] - stamps[0]) * 1e-9 < 4.0
            assert s.monitors.trips["gyro units"] == 1


@pytest.mark.parametrize("lost", [0.0, 0.18])
def test_input_loss_is_counted_against_the_nominal_rate(lost):
    rng = np.random.default_rng(1)
    stamps, acc, gyr = tilting(seconds=20.0)
    keep = rng.random(len(stamps)) >= lost
    s = EstimatorStream(create("vqf"), GateConfig(nominal_rate=RATE))
    s.process_batch(stamps[keep], acc[keep], gyr[keep])
    assert s.loss.share == pytest.approx(lost, abs=0.03)
    assert (s.loss.verdict().level == Level.WARN) == (lost > WARN_SHARE)


def test_input_loss_is_not_fooled_by_bursts():
    """A FIFO read every 20 ms (bursts of samples 10 µs apart) loses nothing: the count, not the steps, is judged."""
    stamps, acc, gyr = tilting(seconds=20.0)
    t = stamps - stamps[0]
    read = (t // 20_000_000 + 1) * 20_000_000
    bursts = stamps[0] + read + (np.arange(len(t)) - np.searchsorted(read, read)) * 10_000
    s = EstimatorStream(create("vqf"), GateConfig(nominal_rate=RATE))
    s.process_batch(bursts, acc, gyr)
    assert s.loss.share < 0.01 and s.loss.verdict().level == Level.OK


def _statuses(diag, name: str) -> list[DiagnosticStatus]:
    return [s for d in diag.messages for s in d.status if s.name.startswith(name + ":")]


@pytest.mark.ros
def test_deg_s_gyro_over_dds_is_an_error_with_one_log_line_and_an_untrusted_covariance(ros, start_node):
    node = start_node("vqf_node", "-p", "input_qos:=reliable", "-p", f"nominal_rate:={RATE}",
                      "-p", "diagnostics_period:=0.5")
    pub = ros.publisher(Imu, "imu/data_raw", reliable=True)
    out = ros.collect(Imu, "imu/vqf/data")
    diag = ros.collect(DiagnosticArray, "/diagnostics")
    wait_matched([pub], [out, diag], f"node to connect (log: {node.output()})")
    stamps, acc, gyr = tilting(seconds=8.0)
    msgs = [imu_msg(int(s), a, g * DEG_S) for s, a, g in zip(stamps, acc, gyr, strict=True)]
    publish_paced(pub, msgs, out.messages, len(msgs))
    wait_for(lambda: any(s.level == DiagnosticStatus.ERROR and "gyro units" in s.message
                         for s in _statuses(diag, "vqf_node")), 10.0, f"an ERROR (log: {node.output()})")
    err = next(s for s in _statuses(diag, "vqf_node") if s.level == DiagnosticStatus.ERROR)
    assert "rad/s" in err.message and "deg/s" in err.message
    log = node.output()
    assert log.count("gyro units:") == 1 and "[ERROR]" in log
    cov = np.array(out.messages[-1].orientation_covariance).reshape(3, 3)
    assert np.allclose(np.diag(cov), UNTRUSTED_SD_RAD ** 2)  # roll, pitch and yaw: not to be trusted
    first = np.array(out.messages[50].orientation_covariance).reshape(3, 3)
    assert first[0, 0] < 0.01  # before the slip was found: the estimator's own
    ros.destroy(pub, out, diag)


@pytest.mark.ros
def test_input_loss_over_dds_is_a_warning(ros, start_node):
    node = start_node("madgwick_node", "-p", "input_qos:=reliable", "-p", f"nominal_rate:={RATE}",
                      "-p", "diagnostics_period:=0.5")
    pub = ros.publisher(Imu, "imu/data_raw", reliable=True)
    out = ros.collect(Imu, "imu/madgwick/data")
    diag = ros.collect(DiagnosticArray, "/diagnostics")
    wait_matched([pub], [out, diag], f"node to connect (log: {node.output()})")
    stamps, acc, gyr = tilting(seconds=15.0)
    keep = np.random.default_rng(3).random(len(stamps)) >= 0.18
    msgs = [imu_msg(int(s), a, g) for s, a, g in zip(stamps[keep], acc[keep], gyr[keep], strict=True)]
    publish_paced(pub, msgs, out.messages, len(msgs))
    wait_for(lambda: any(s.level == DiagnosticStatus.WARN and "input loss" in s.message
                         for s in _statuses(diag, "madgwick_node")), 10.0, f"a WARN (log: {node.output()})")
    values = {kv.key: kv.value for kv in _statuses(diag, "madgwick_node")[-1].values}
    assert 12.0 < float(values["input lost (%, last 10 s)"]) < 24.0
    assert node.output().count("input loss:") == 1
    ros.destroy(pub, out, diag)


@pytest.mark.ros
@pytest.mark.parametrize("what", ["nan", "stale"])
def test_field_readings_the_node_cannot_use_are_counted_and_named(ros, start_node, what):
    """Magnetometer readings that arrive but cannot be used (NaN, or stamped a second before the IMU's) are counted
    by cause and named in /diagnostics (WARN), not reported as "no field received"."""
    from sensor_msgs.msg import MagneticField

    from riann_ros import stamps as st_ns

    node = start_node("vqf_node", "-p", "input_qos:=reliable", "-p", f"nominal_rate:={RATE}",
                      "-p", "diagnostics_period:=0.3")
    pub = ros.publisher(Imu, "imu/data_raw", reliable=True)
    pub_mag = ros.publisher(MagneticField, "imu/mag", reliable=True)
    out = ros.collect(Imu, "imu/vqf/data")
    diag = ros.collect(DiagnosticArray, "/diagnostics")
    wait_matched([pub, pub_mag], [out, diag], f"node to connect (log: {node.output()})")
    stamps, acc, gyr = tilting(seconds=3.0)
    for k, (s, a, g) in enumerate(zip(stamps, acc, gyr, strict=True)):
        if k % 2 == 0:
            m = MagneticField()
            st_ns.set_ns(m.header.stamp, int(s) - (1_000_000_000 if what == "stale" else 0))
            v = (math.nan,) * 3 if what == "nan" else (20e-6, 0.0, -40e-6)
            m.magnetic_field.x, m.magnetic_field.y, m.magnetic_field.z = v
            pub_mag.publish(m)
        pub.publish(imu_msg(int(s), a, g))
        while k - len(out.messages) >= 50:
            wait_for(lambda k=k: k - len(out.messages) < 50, 30.0, "the node to keep up")
    cause = "not finite" if what == "nan" else "stale"

    def named() -> bool:
        return any(s.level == DiagnosticStatus.WARN and "magnetometer readings" in s.message and cause in s.message
                   for s in _statuses(diag, "vqf_node"))

    wait_for(named, 30.0, f"a WARN naming '{cause}' (log: {node.output()})")
    values = {kv.key: kv.value for kv in _statuses(diag, "vqf_node")[-1].values}
    assert int(values[f"field readings {cause} (total)"]) > 100
    assert "no field received" not in values["magnetometer"]
    ros.destroy(pub, pub_mag, out, diag)
