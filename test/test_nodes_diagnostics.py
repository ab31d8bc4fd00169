"""The node's /diagnostics and its stamp-rate check (riann_ros.nodes.diagnostics): the measured rate is a robust
median; a nominal_rate that does not fit the stamps gives one warning naming both rates and the parameter, WARN in
/diagnostics until nominal_rate is set; an accelerometer in g is WARN until a restart shows m/s², zero stamps WARN
while they arrive, a period whose every message is rejected ERROR (tested in-process, then over DDS with the node
executables)."""

from __future__ import annotations

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import QuaternionStamped
from rcl_interfaces.srv import SetParameters
from sensor_msgs.msg import Imu
from test_nodes_outputs import motion, send, wait_connected
from test_nodes_parameters import _param_client, _set

from conftest import wait_for
from helpers_ros import quats
from riann_ros.nodes.diagnostics import StampRateCheck
from riann_ros.nodes.madgwick_node import MadgwickNode
from riann_ros.nodes.riann_node import RiannNode
from riann_ros.nodes.vqf_node import VqfNode


def test_stamp_rate_check_is_a_robust_median():
    rng = np.random.default_rng(0)
    c = StampRateCheck(samples=100, tolerance=0.1)
    dts = np.full(100, 1 / 200.0) + rng.normal(0, 2e-4, 100)
    dts[[5, 50]] = [0.3, 1e-6]  # a gap and a burst
    done = [c.add(float(dt)) for dt in dts]
    assert done == [False] * 99 + [True]
    assert c.measured_hz == pytest.approx(200.0, rel=0.01)
    assert not c.add(0.01)  # measured once
    assert c.mismatch(200.0) is None and c.mismatch(185.0) is None  # within 10 %
    assert c.mismatch(100.0) == pytest.approx(1.0, rel=0.02)
    text = c.text(100.0)
    assert "rate 199.6 Hz" in text and "nominal_rate 100.0 Hz" in text and "set the parameter nominal_rate" in text
    assert StampRateCheck().mismatch(100.0) is None  # not measured yet
    c2 = StampRateCheck(samples=3)
    assert not c2.add(0.0) and not c2.add(float("nan"))  # no time step: not counted


def _diag_of(diag, node_name: str):
    return [s for d in diag.messages for s in d.status if s.name.startswith(node_name + ":")]


@pytest.mark.ros
def test_rate_warning_when_nominal_rate_is_wrong(ros, start_node):
    """200 Hz stamps into a node left at nominal_rate 100: one warning naming both rates and the parameter,
    WARN in /diagnostics until nominal_rate is set (as an int, at run time); a node set right stays quiet."""
    wrong = start_node("vqf_node", "-p", "input_qos:=reliable", "-p", "diagnostics_period:=0.2")
    right = start_node("madgwick_node", "-p", "input_qos:=reliable", "-p", "nominal_rate:=200",
                       "-p", "diagnostics_period:=0.2")
    pub = ros.publisher(Imu, "imu/data_raw")
    att = [ros.collect(QuaternionStamped, c.ATTITUDE_TOPIC) for c in (VqfNode, MadgwickNode)]
    diag = ros.collect(DiagnosticArray, "/diagnostics")
    wait_connected(pub, att, [wrong, right], n_subs=2)
    stamps, acc, gyr = motion(160)
    stamps[80:] += 300_000_000  # one gap (restart) inside: the median does not care
    send(pub, stamps, acc, gyr, period=0.002)
    wait_for(lambda: all(len(c.messages) >= 160 for c in att), 20, "outputs")
    wait_for(lambda: "measured IMU stamp rate" in wrong.output(), 5, f"the warning (log: {wrong.output()})")
    log = wrong.output()
    assert log.count("measured IMU stamp rate") == 1
    assert "measured IMU stamp rate 200.0 Hz" in log and "nominal_rate 100.0 Hz" in log
    assert "set the parameter nominal_rate to 200.0" in log
    assert "measured IMU stamp rate" not in right.output()

    def latest(node_name):
        st = _diag_of(diag, node_name)
        return st[-1] if st else None

    def value(status, key):
        return {kv.key: kv.value for kv in status.values}[key]

    wait_for(lambda: (s := latest("vqf_node")) is not None and "nominal_rate" in s.message, 5, "WARN diagnostics")
    s = latest("vqf_node")
    assert s.level == DiagnosticStatus.WARN and "measured stamp rate 200.0 Hz" in s.message
    assert value(s, "stamp rate measured (Hz)") == "200.00" and value(s, "nominal_rate (Hz)") == "100.00"
    # its latest status may predate its 100th sample (no ordering between two nodes' timers): wait for one after
    wait_for(lambda: (s := latest("madgwick_node")) is not None and value(s, "stamp rate measured (Hz)") != "nan", 5,
             "madgwick_node's measured rate in /diagnostics")
    assert value(latest("madgwick_node"), "stamp rate measured (Hz)") == "200.00"
    assert "differs from the measured stamp rate" not in latest("madgwick_node").message
    set_ = _param_client(ros, SetParameters, "vqf_node", "set_parameters")
    assert _set(set_, "nominal_rate", 200) == (True, "")
    wait_for(lambda: value(latest("vqf_node"), "nominal_rate (Hz)") == "200.00", 5, "diagnostics after the set")
    assert "nominal_rate" not in latest("vqf_node").message
    ros.node.destroy_client(set_)
    ros.destroy(pub, *att, diag)


@pytest.mark.ros
def test_acc_in_g_is_warn_until_a_restart_shows_m_s2(ros, start_node):
    """An accelerometer in g (a sensor at rest, rolled 20°): the node's estimate is wrong and /diagnostics says so,
    WARN naming g, the measured |acc| and the fix; after the driver restarts in m/s² (its clock jumps back) the check
    runs anew and the status returns to OK. A period whose every message is rejected (NaN) is ERROR, zero header
    stamps are WARN while they arrive."""
    node = start_node("riann_node", "-p", "input_qos:=reliable", "-p", "nominal_rate:=200",
                      "-p", "diagnostics_period:=0.2")
    pub = ros.publisher(Imu, "imu/data_raw")
    att = ros.collect(QuaternionStamped, RiannNode.ATTITUDE_TOPIC)
    diag = ros.collect(DiagnosticArray, "/diagnostics")
    wait_connected(pub, [att], [node])
    roll = np.radians(20.0)
    acc = np.tile([0.0, 9.80665 * np.sin(roll), 9.80665 * np.cos(roll)], (300, 1))
    gyr = np.zeros((300, 3))
    stamps = 1_000_000_000_000 + np.arange(300) * 5_000_000
    send(pub, stamps, acc / 9.80665, gyr)  # in g

    def latest():
        st = _diag_of(diag, "riann_node")
        return st[-1] if st else None

    wait_for(lambda: (s := latest()) is not None and "accelerometer in g" in s.message, 10,
             f"WARN for g (log: {node.output()})")
    s = latest()
    assert s.level == DiagnosticStatus.WARN, s.message
    assert "median |acc| 1.00" in s.message and "estimates are wrong" in s.message and "9.80665" in s.message
    assert {kv.key: kv.value for kv in s.values}["accelerometer median |acc| at (re)start (m/s2)"] == "1.00"
    wait_for(lambda: len(att.messages) >= 300, 10, "outputs")
    q = quats(att.messages[-1:])[0]
    est_roll = np.degrees(np.arctan2(2 * (q[0] * q[1] + q[2] * q[3]), 1 - 2 * (q[1] ** 2 + q[2] ** 2)))
    assert abs(est_roll - 20.0) > 2.0  # the estimate is wrong indeed (the network was trained on m/s²)
    send(pub, stamps[:300], acc, gyr)  # the driver restarted in m/s²: its clock starts again (a jump back)
    wait_for(lambda: (s := latest()) is not None and s.level == DiagnosticStatus.OK and s.message == "ok", 10,
             f"OK after the restart in m/s² (latest: {latest().message})")
    assert {kv.key: kv.value for kv in latest().values}["accelerometer median |acc| at (re)start (m/s2)"] == "9.81"
    log = node.output()
    assert log.count("seems to report in g") == 1 and "in m/s² as REP-145 wants" in log
    bad = np.full((200, 3), np.nan)
    send(pub, stamps[:200] + 2_000_000_000, bad, gyr[:200])  # 0.6 s of nothing usable
    wait_for(lambda: (s := latest()) is not None and s.level == DiagnosticStatus.ERROR, 10, "ERROR")
    assert latest().message.startswith("no estimate published: all") and "non_finite=" in latest().message
    send(pub, np.zeros(200, dtype=np.int64), acc[:200], gyr[:200])  # a driver that does not stamp
    wait_for(lambda: (s := latest()) is not None and "zero header stamps" in s.message, 10, "WARN for zero stamps")
    assert latest().level == DiagnosticStatus.WARN
    ros.destroy(pub, att, diag)
