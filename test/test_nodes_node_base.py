"""riann_node over real DDS: one output per input, equal to the core, bad input, reset, diagnostics."""

from __future__ import annotations

import itertools
import time

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import QuaternionStamped
from sensor_msgs.msg import Imu
from std_srvs.srv import Trigger

from conftest import ROOT, rmse, wait_for, wait_matched
from helpers_ros import imu_msg, publish_paced, quats, stamp_ns
from riann_ros.cli.live import call_service
from riann_ros.estimators import create
from riann_ros.stream import EstimatorStream, GateConfig

pytestmark = pytest.mark.ros


def connect(ros, node, att_topic="imu/attitude", reliable_in=True):
    pub = ros.publisher(Imu, "imu/data_raw", reliable=reliable_in)
    att = ros.collect(QuaternionStamped, att_topic)
    wait_matched([pub], [att], f"node to connect (log: {node.output()})")
    return pub, att


def test_node_output_equals_core_on_a_broad_trial(ros, start_node, broad_trial):
    rec = broad_trial("33")
    node = start_node("riann_node", "-p", "input_qos:=reliable", "-p", "input_depth:=1000",
                      "-p", f"nominal_rate:={rec.rate_hz}")
    pub, att = connect(ros, node)
    imu_out = ros.collect(Imu, "imu/data")
    wait_matched([], [imu_out], "imu/data")
    stamps = rec.stamps_ns + 1_700_000_000_000_000_000  # BROAD starts at 0; a zero stamp means "unstamped"
    msgs = [imu_msg(s, a, g) for s, a, g in zip(stamps, rec.acc, rec.gyr, strict=True)]
    t0 = time.monotonic()
    try:
        publish_paced(pub, msgs, att.messages, len(msgs))
    except AssertionError as e:
        raise AssertionError(f"{e}; node log: {node.output()[-3000:]}") from None
    time.sleep(0.2)
    print(f"{len(msgs)} messages through riann_node in {time.monotonic() - t0:.1f} s")
    got = att.messages
    assert len(got) == len(msgs), f"{len(got)} outputs for {len(msgs)} inputs"
    assert [stamp_ns(m) for m in got] == stamps.tolist()
    assert all(m.header.frame_id == "odom" for m in got[:100])  # fixed_frame: the orientation's frame
    q_node = quats(got)
    core = EstimatorStream(create("riann"), GateConfig(nominal_rate=rec.rate_hz))
    q_core, ok = core.process_batch(stamps, rec.acc, rec.gyr)
    assert ok.all()
    assert np.abs(q_node - q_core).max() < 1e-4
    e_node = rmse(rec, q_node)
    e_core = rmse(rec, q_core)
    assert abs(e_node - e_core) < 0.01 and 0.2 < e_node < 3.0
    # imu/data's covariance (orientation_covariance: model, the default) is the offline σ, SPD on every message
    wait_for(lambda: len(imu_out.messages) >= len(msgs), 30, "imu/data")
    cov = np.array([m.orientation_covariance for m in imu_out.messages])
    want = np.zeros_like(cov)
    want[:, 0] = want[:, 4] = core.batch_sigma[:, 0] ** 2
    want[:, 8] = core.batch_sigma[:, 1] ** 2
    assert np.abs(cov - want).max() < 1e-6
    assert (np.abs(cov[:, 0] - want[:, 0]) < 1e-2 * want[:, 0]).all()  # relative, too (float32 GRU round-off)
    assert (np.linalg.eigvalsh(cov.reshape(-1, 3, 3)) > 0.0).all()
    assert np.sqrt(cov[:, 0]).max() > 3.0 * np.sqrt(cov[:, 0]).min()  # per sample, not a constant
    ros.destroy(pub, att, imu_out)


def test_node_output_equals_core_on_a_regular_low_rate_stream(ros, start_node, broad_trial):
    """A BROAD trial made a regular 50 Hz stream of a low-pass sensor (``rate:50:lowpass``): the grid up-samples it
    and reads each sample a quarter step before its stamp (``sample_delay``); the node equals the core."""
    from riann_ros.evaluation.perturb import parse_perturbation

    rec = parse_perturbation("rate:50:lowpass").start(np.random.default_rng(0))(broad_trial("33"))
    node = start_node("riann_node", "-p", "input_qos:=reliable", "-p", "input_depth:=1000", "-p", "nominal_rate:=50.0")
    pub, att = connect(ros, node)
    stamps = rec.stamps_ns + 1_700_000_000_000_000_000
    msgs = [imu_msg(s, a, g) for s, a, g in zip(stamps, rec.acc, rec.gyr, strict=True)]
    try:
        publish_paced(pub, msgs, att.messages, len(msgs))
    except AssertionError as e:
        raise AssertionError(f"{e}; node log: {node.output()[-3000:]}") from None
    time.sleep(0.2)
    got = att.messages
    assert len(got) == len(msgs), f"{len(got)} outputs for {len(msgs)} inputs"
    q_node = quats(got)
    est = create("riann")
    q_core, ok = EstimatorStream(est, GateConfig(nominal_rate=50.0)).process_batch(stamps, rec.acc, rec.gyr)
    assert ok.all()
    assert est.timeline is not None and est.timeline.delay() == pytest.approx(0.005, rel=1e-3)
    assert np.abs(q_node - q_core).max() < 1e-4
    assert abs(rmse(rec, q_node) - rmse(rec, q_core)) < 0.01
    ros.destroy(pub, att)


def synthetic(n: int, rate: float = 200.0, t0_ns: int = 1_000_000_000):
    rng = np.random.default_rng(3)
    stamps = t0_ns + (np.arange(n) * 1e9 / rate).astype(np.int64)
    acc = np.array([0.5, -0.3, 9.7]) + rng.normal(0, 0.2, (n, 3))
    gyr = rng.normal(0, 0.2, (n, 3))
    return stamps, acc, gyr


def send_slowly(pub, msgs, period=0.002):
    for m in msgs:
        pub.publish(m)
        time.sleep(period)


def test_bad_input_is_rejected_or_restarts_as_documented(ros, start_node):
    node = start_node("riann_node", "-p", "input_qos:=reliable", "-p", "nominal_rate:=200.0", "-p", "max_dt:=0.5")
    pub, att = connect(ros, node)
    diag = ros.collect(DiagnosticArray, "/diagnostics")
    stamps, acc, gyr = synthetic(120)
    stamps = stamps.copy()
    acc = acc.copy()
    acc[10] = [np.nan, 0.0, 9.8]  # non-finite: skipped, state untouched
    gyr[11] = [np.inf, 0.0, 0.0]
    stamps[20] = stamps[19]  # repeated stamp
    stamps[30] = stamps[29] - 1_000_000  # 1 ms back: out of order, rejected
    stamps[60:] += 2_000_000_000  # 2 s gap: restart
    stamps[90:] -= 10_000_000_000  # 10 s back (bag loop): restart
    msgs = [imu_msg(s, a, g) for s, a, g in zip(stamps, acc, gyr, strict=True)]
    send_slowly(pub, msgs)
    expected, ok = EstimatorStream(create("riann"), GateConfig(nominal_rate=200.0, max_dt=0.5)).process_batch(
        stamps, acc, gyr)
    assert ok.sum() == 120 - 4
    wait_for(lambda: len(att.messages) >= ok.sum(), 20, "outputs")
    time.sleep(0.3)
    got = att.messages
    assert len(got) == ok.sum()
    assert [stamp_ns(m) for m in got] == stamps[ok].tolist()
    assert np.abs(quats(got) - expected[ok]).max() < 1e-4
    # and the restarts really restarted: a fresh estimator on the tail gives the same outputs
    fresh = create("riann")
    q_tail = fresh.update_batch(acc[90:], gyr[90:], np.r_[1 / 200.0, np.diff(stamps[90:]) * 1e-9])
    assert np.abs(quats(got)[-30:] - q_tail).max() < 1e-4
    log = node.output()
    assert "gap at stamp" in log and "clock jump at stamp" in log
    assert "non_finite" in log
    def counted(d) -> bool:  # a diagnostics message published after every sample was taken
        v = {kv.key: kv.value for kv in d.status[0].values}
        return all(v.get(k, "0") != "0" for k in ("rejected non_finite (total)", "restarts gap (total)",
                                                   "restarts clock_jump (total)"))

    # (the clock jump is the last event: a message published before it was processed does not count)
    wait_for(lambda: any(counted(d) for d in diag.messages), 5, "diagnostics with rejections and restarts")
    status = [d for d in diag.messages if counted(d)][-1].status[0]
    values = {kv.key: kv.value for kv in status.values}
    assert values["rejected non_finite (total)"] == "2"
    assert values["rejected stamp_repeat (total)"] == "1"
    assert values["rejected stamp_backwards (total)"] == "1"
    assert values["restarts gap (total)"] == "1" and values["restarts clock_jump (total)"] == "1"
    assert "riann_node" in status.name
    assert float(values["inference time max (us)"]) > 0.0 and float(values["input rate (Hz)"]) >= 0.0
    ros.destroy(pub, att, diag)


def test_imu_data_carries_input_with_orientation_and_covariance(ros, start_node):
    node = start_node("riann_node", "-p", "input_qos:=reliable", "-p", "yaw_stddev_deg:=90.0",
                      "-p", "orientation_covariance:=constant")
    pub, att = connect(ros, node)
    imu_out = ros.collect(Imu, "imu/data")
    wait_matched([], [imu_out], "imu/data")
    stamps, acc, gyr = synthetic(50)
    send_slowly(pub, [imu_msg(s, a, g, frame_id="my_imu") for s, a, g in zip(stamps, acc, gyr, strict=True)])
    wait_for(lambda: len(imu_out.messages) >= 50 and len(att.messages) >= 50, 10, "outputs")
    for m_imu, m_att, s, a, g in zip(imu_out.messages, att.messages, stamps, acc, gyr, strict=True):
        assert stamp_ns(m_imu) == stamp_ns(m_att) == s
        assert m_imu.header.frame_id == "my_imu"  # imu/data: the input's sensor frame (REP-145)
        assert m_att.header.frame_id == "odom"  # imu/attitude: expressed in fixed_frame
        o, q = m_imu.orientation, m_att.quaternion
        assert (o.x, o.y, o.z, o.w) == (q.x, q.y, q.z, q.w)
        assert abs(o.x**2 + o.y**2 + o.z**2 + o.w**2 - 1.0) < 1e-6
        assert (m_imu.linear_acceleration.x, m_imu.angular_velocity.z) == (a[0], g[2])
        cov = np.array(m_imu.orientation_covariance).reshape(3, 3)
        assert cov[0, 0] == cov[1, 1] == pytest.approx(np.radians(2.0) ** 2)
        assert cov[2, 2] == pytest.approx(np.radians(90.0) ** 2)
    ros.destroy(pub, att, imu_out)


def test_zero_stamps_use_receive_time_and_g_units_warn(ros, start_node):
    node = start_node("riann_node", "-p", "input_qos:=reliable")
    pub, att = connect(ros, node)
    _, acc, gyr = synthetic(80)
    send_slowly(pub, [imu_msg(0, a / 9.81, g) for a, g in zip(acc, gyr, strict=True)], period=0.005)
    wait_for(lambda: len(att.messages) >= 80, 10, "outputs")
    s = [stamp_ns(m) for m in att.messages]
    assert all(x > 0 for x in s) and all(b > a for a, b in itertools.pairwise(s))
    log = node.output()
    assert log.count("zero header stamps") == 1
    assert log.count("seems to report in g") == 1
    ros.destroy(pub, att)


def test_reset_service_clears_state(ros, start_node):
    node = start_node("riann_node", "-p", "input_qos:=reliable", "-p", "nominal_rate:=200.0")
    pub, att = connect(ros, node)
    stamps, acc, gyr = synthetic(60)
    msgs = [imu_msg(s, a, g) for s, a, g in zip(stamps, acc, gyr, strict=True)]
    send_slowly(pub, msgs[:30])
    wait_for(lambda: len(att.messages) >= 30, 10, "first half")
    client = ros.node.create_client(Trigger, "/riann_node/reset")
    assert client.wait_for_service(timeout_sec=10)
    res = call_service(client, Trigger.Request(), 10)
    assert res is not None and res.success, "no answer from ~/reset"
    send_slowly(pub, msgs[30:])
    wait_for(lambda: len(att.messages) >= 60, 10, "second half")
    q = create("riann").update_batch(acc[30:], gyr[30:], np.r_[1 / 200.0, np.diff(stamps[30:]) * 1e-9])
    assert np.abs(quats(att.messages[30:]) - q).max() < 1e-4
    ros.node.destroy_client(client)
    ros.destroy(pub, att)


@pytest.mark.parametrize("reliable", [True, False])
def test_default_qos_connects_to_reliable_and_best_effort_drivers(ros, start_node, reliable):
    node = start_node("riann_node", "--params-file", str(ROOT / "config" / "riann.yaml"))
    pub, att = connect(ros, node, reliable_in=reliable)
    stamps, acc, gyr = synthetic(60)
    send_slowly(pub, [imu_msg(s, a, g) for s, a, g in zip(stamps, acc, gyr, strict=True)], period=0.01)
    # best effort loses the first few messages while the reader side is still matching: that is DDS
    wait_for(lambda: len(att.messages) >= 40, 10, f"outputs ({len(att.messages)}; log: {node.output()})")
    assert "input_qos=sensor_data" in node.output()
    ros.destroy(pub, att)


def test_runtime_parameter_validation(ros, start_node):
    from rcl_interfaces.msg import Parameter as ParamMsg
    from rcl_interfaces.msg import ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters

    node = start_node("madgwick_node")
    client = ros.node.create_client(SetParameters, "/madgwick_node/set_parameters")
    assert client.wait_for_service(timeout_sec=15), node.output()

    def set_beta(v: float) -> bool:
        req = SetParameters.Request()
        req.parameters = [ParamMsg(name="beta", value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE,
                                                                     double_value=v))]
        res = call_service(client, req, 10)
        assert res is not None, "no answer from set_parameters"
        return res.results[0].successful

    assert set_beta(0.1)
    assert not set_beta(-1.0)  # outside the declared range
    ros.node.destroy_client(client)
