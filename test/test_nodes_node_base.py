"""The node base (riann_ros.nodes.node_base) over real DDS, with riann_node: one output per input, equal to the core,
bad input, reset, diagnostics, QoS, run-time parameters, and the magnetometer input on imu/mag."""

from __future__ import annotations

import itertools
import time

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import QuaternionStamped
from sensor_msgs.msg import Imu, MagneticField
from std_srvs.srv import Trigger

from conftest import ROOT, rmse, wait_for, wait_matched
from helpers_ros import imu_msg, publish_paced, quats, stamp_ns
from riann_ros import quaternion as quat
from riann_ros import stamps as st_ns
from riann_ros.estimators import create
from riann_ros.magcal.input import FIELD_STALE, FIELD_USED, MagConfig, pair_fields
from riann_ros.ros.services import call_service
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
    # (relative: the heading σ holds the calibration's doubt, a function of the attitude the network gives to 1e-5)
    np.testing.assert_allclose(cov, want, rtol=1e-4, atol=1e-6)
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


# -- the magnetometer: a 400 Hz IMU with a 100 Hz sensor_msgs/MagneticField on imu/mag ---------------------------
# One output per IMU message, equal to the offline path (the bag reader's pairing + EstimatorStream) within 1e-4;
# when the magnetometer stops the node goes on without a gap (heading held by the gyro, 6D in /diagnostics) and
# goes back to 9D when the field returns.
RATE = 400.0
MAG_EVERY = 4  # 100 Hz
FIELD_ENU = np.array([0.0, 20e-6, -40e-6])  # T, y = magnetic north, a downward vertical component
T0 = 1_700_000_000_000_000_000


def motion(n: int, seed: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Stamps, acc, gyr and the field in the sensor frame of a smooth rotation (tilt and a slow turn)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / RATE
    gyr = np.column_stack([0.4 * np.sin(0.7 * t), 0.3 * np.cos(0.5 * t), 0.5 * np.sin(0.2 * t + 0.3)])
    gyr += rng.normal(0.0, 0.002, gyr.shape)
    q = np.empty((n, 4))
    q[0] = quat.from_rotvec([0.2, -0.1, 0.4])
    steps = quat.from_rotvec(gyr[1:] / RATE)
    for i in range(1, n):
        q[i] = quat.multiply(q[i - 1], steps[i - 1])
    inv = quat.conjugate(q)
    acc = quat.rotate(inv, np.tile([0.0, 0.0, 9.81], (n, 1))) + rng.normal(0.0, 0.05, (n, 3))
    mag = quat.rotate(inv, np.tile(FIELD_ENU, (n, 1))) + rng.normal(0.0, 0.3e-6, (n, 3))
    stamps = T0 + np.round(t * 1e9).astype(np.int64)
    return stamps, acc, gyr, mag


def mag_msg(stamp: int, m) -> MagneticField:
    msg = MagneticField()
    st_ns.set_ns(msg.header.stamp, int(stamp))
    msg.header.frame_id = "imu_link"
    msg.magnetic_field.x, msg.magnetic_field.y, msg.magnetic_field.z = (float(v) for v in m)
    return msg


def send(ros, pub_imu, pub_mag, att, stamps, acc, gyr, mag, mag_until: int, window: int = 50) -> list[int]:
    """IMU messages in order; a field reading every MAG_EVERY samples before ``mag_until``, published two IMU periods
    ahead of its stamp (so it is there when the IMU message of that stamp arrives). Returns the field indices sent."""
    sent = []
    for i in range(len(stamps)):
        j = i + 2
        if j < min(len(stamps), mag_until) and j % MAG_EVERY == 0:
            pub_mag.publish(mag_msg(stamps[j], mag[j]))
            sent.append(j)
        while i - len(att.messages) >= window:
            time.sleep(0.0002)
        pub_imu.publish(imu_msg(stamps[i], acc[i], gyr[i]))
        time.sleep(0.0005)
    return sent


def offline(stamps, acc, gyr, mag, sent: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """The offline estimates and their σ (inclination, heading; rad)."""
    fields = pair_fields(stamps, stamps[sent], mag[sent], MagConfig().timeout_ns)
    stream = EstimatorStream(create("riann"), GateConfig(nominal_rate=RATE))
    q, ok = stream.process_batch(stamps, acc, gyr, fields)
    assert ok.all()
    return q, stream.batch_sigma


def test_400hz_imu_with_100hz_mag_equals_offline_and_survives_the_mag_stopping(ros, start_node):
    node = start_node("riann_node", "-p", "input_qos:=reliable", "-p", f"nominal_rate:={RATE}",
                      "-p", "diagnostics_period:=0.2")
    pub_imu = ros.publisher(Imu, "imu/data_raw")
    pub_mag = ros.publisher(MagneticField, "imu/mag")
    att = ros.collect(QuaternionStamped, "imu/attitude")
    imu_out = ros.collect(Imu, "imu/data")
    diags = ros.collect(DiagnosticArray, "/diagnostics")
    wait_matched([pub_imu, pub_mag], [att, imu_out], f"node to connect (log: {node.output()})")
    n = int(12 * RATE)
    stamps, acc, gyr, mag = motion(n)
    # the magnetometer stops after 6 s (its publisher goes away) and comes back for the last 3 s
    sent = send(ros, pub_imu, pub_mag, att, stamps[: n // 2], acc, gyr, mag, mag_until=n // 2)
    ros.destroy(pub_mag)
    stale_from = len(att.messages)
    sent_b = send(ros, pub_imu, None, att, stamps[n // 2 : 3 * n // 4], acc[n // 2 :], gyr[n // 2 :], None,
                  mag_until=0)
    wait_for(lambda: len(att.messages) >= 3 * n // 4, 20, "outputs while the magnetometer is gone")
    time.sleep(0.5)  # a diagnostics period with the field stale
    states_gone = [kv.value for d in diags.messages for s in d.status for kv in s.values if kv.key == "magnetometer"]
    pub_mag2 = ros.publisher(MagneticField, "imu/mag")
    wait_matched([pub_mag2], [], "the magnetometer to reconnect")
    rest = slice(3 * n // 4, n)
    sent_c = send(ros, pub_imu, pub_mag2, att, stamps[rest], acc[rest], gyr[rest], mag[rest], mag_until=n)
    sent_c = [3 * n // 4 + j for j in sent_c]
    wait_for(lambda: len(att.messages) >= n, 30, f"all outputs ({len(att.messages)} of {n})")
    time.sleep(0.5)
    assert not sent_b
    got = att.messages
    assert [stamp_ns(m) for m in got] == stamps.tolist(), "one output per IMU message, in order, no gap"
    q_off, sigma = offline(stamps, acc, gyr, mag, sent + sent_c)
    q_node = quats(got)
    d = np.minimum(np.abs(q_node - q_off).max(axis=1), np.abs(q_node + q_off).max(axis=1))  # q ≡ −q (w ≈ 0)
    assert d.max() < 1e-4, np.flatnonzero(d > 1e-4)[:10]
    # 9D while the field comes: the heading is absolute (ENU, magnetic north) -> close to the truth
    q_true = np.empty((n, 4))
    q_true[0] = quat.from_rotvec([0.2, -0.1, 0.4])
    steps = quat.from_rotvec(gyr[1:] / RATE)
    for i in range(1, n):
        q_true[i] = quat.multiply(q_true[i - 1], steps[i - 1])
    heading = np.degrees(quat.heading_error(q_true, quats(got)))
    assert heading[int(3 * RATE): n // 2].max() < 3.0, heading[int(3 * RATE): n // 2].max()
    assert heading[stale_from: 3 * n // 4].max() < 3.0  # held by the gyro while the field is gone
    # diagnostics named the fallback, and the return to 9D; the yaw covariance follows
    assert any(v == FIELD_STALE for v in states_gone), states_gone[-5:]
    final = [kv.value for s in diags.messages[-1].status for kv in s.values if kv.key == "magnetometer"]
    assert final == [FIELD_USED]
    # imu/data's covariance is the offline σ (orientation_covariance: model), SPD on every message; the yaw σ is the
    # field's while it corrects and grows while the field is gone
    cov = np.array([m.orientation_covariance for m in imu_out.messages])
    assert len(cov) == n
    want = np.zeros((n, 9))
    want[:, 0] = want[:, 4] = sigma[:, 0] ** 2
    want[:, 8] = sigma[:, 1] ** 2
    # (relative: the heading σ holds the calibration's doubt, a function of the attitude the network gives to 1e-5)
    np.testing.assert_allclose(cov, want, rtol=1e-4, atol=1e-6)
    assert (np.linalg.eigvalsh(cov.reshape(n, 3, 3)) > 0.0).all()
    yaw_sd = np.degrees(np.sqrt(cov[:, 8]))
    corrected = yaw_sd[int(3 * RATE): n // 2]  # the field's 2.6° and the tilt's share (the bias still unknown here)
    held = yaw_sd[stale_from + int(RATE): 3 * n // 4]
    assert 2.6 <= corrected.min() and corrected.max() < 30.0 and 2.6 <= yaw_sd[-1] < 30.0
    assert held.max() < 180.0 and held.max() > yaw_sd[-1]  # the gyro's drift while the field is gone
    log = node.output()
    assert f"magnetometer: {FIELD_STALE}" in log and f"magnetometer: {FIELD_USED}" in log
    ros.destroy(pub_imu, pub_mag2, att, imu_out, diags)
