"""Node outputs in the chosen world frame, fixed_frame, imu/rpy, TF, integer parameters, the rate warning.

Pure parts (the TF message, the stamp-rate check, the rpy topic names) are tested in-process; the rest
over real DDS with the node executables (they import riann_ros from PYTHONPATH, i.e. this tree).
"""

from __future__ import annotations

import time

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import QuaternionStamped, Vector3Stamped
from rcl_interfaces.msg import Parameter as ParamMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import GetParameters, SetParameters
from sensor_msgs.msg import Imu

from conftest import wait_for, wait_matched
from helpers_ros import imu_msg, quats, stamp_ns
from riann_ros import frames
from riann_ros.cli.live import call_service
from riann_ros.estimators import create
from riann_ros.nodes.diagnostics import StampRateCheck
from riann_ros.nodes.madgwick_node import MadgwickNode
from riann_ros.nodes.mahony_node import MahonyNode
from riann_ros.nodes.outputs import make_transform, rpy_topic, tf_frames_problem
from riann_ros.nodes.riann_node import RiannNode
from riann_ros.nodes.vqf_node import VqfNode
from riann_ros.stream import EstimatorStream, GateConfig

H = np.sqrt(0.5)
G = 9.81
NODES = {"riann": RiannNode, "madgwick": MadgwickNode, "mahony": MahonyNode, "vqf": VqfNode}


# -- pure parts ------------------------------------------------------------------------------------------
def test_rpy_topics_follow_the_attitude_topics():
    assert {n: rpy_topic(c.ATTITUDE_TOPIC) for n, c in NODES.items()} == {
        "riann": "imu/rpy", "madgwick": "imu/madgwick/rpy", "mahony": "imu/mahony/rpy", "vqf": "imu/vqf/rpy"}


def test_transform_is_fixed_frame_to_sensor_frame_rotation_only():
    from builtin_interfaces.msg import Time

    q = tuple(frames.to_world(frames.from_rpy_deg(10.0, -5.0, 30.0), "ned"))
    t = make_transform(Time(sec=12, nanosec=345), "odom", "imu_link", q)
    assert (t.header.stamp.sec, t.header.stamp.nanosec) == (12, 345)
    assert (t.header.frame_id, t.child_frame_id) == ("odom", "imu_link")
    r = t.transform.rotation
    assert (r.w, r.x, r.y, r.z) == q
    tr = t.transform.translation
    assert (tr.x, tr.y, tr.z) == (0.0, 0.0, 0.0)
    assert tf_frames_problem("odom", "imu_link") is None
    assert "empty" in tf_frames_problem("odom", "")
    assert "its own parent" in tf_frames_problem("odom", "/odom")


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


# -- over DDS ---------------------------------------------------------------------------------------------
def level(n: int, rate: float = 200.0, t0_ns: int = 1_000_000_000):
    stamps = t0_ns + (np.arange(n) * 1e9 / rate).astype(np.int64)
    return stamps, np.tile([0.0, 0.0, G], (n, 1)), np.zeros((n, 3))


def motion(n: int, rate: float = 200.0, t0_ns: int = 1_000_000_000):
    rng = np.random.default_rng(7)
    stamps = t0_ns + (np.arange(n) * 1e9 / rate).astype(np.int64)
    acc = np.array([1.5, -2.0, 9.3]) + rng.normal(0, 0.3, (n, 3))
    gyr = rng.normal(0, 0.4, (n, 3))
    return stamps, acc, gyr


def send(pub, stamps, acc, gyr, frame_id="imu_link", period=0.003):
    for s, a, g in zip(stamps, acc, gyr, strict=True):
        pub.publish(imu_msg(s, a, g, frame_id=frame_id))
        time.sleep(period)


def remap(prefix: str) -> tuple[str, ...]:
    """Remap one node's outputs under ``prefix`` and give it its own name (two of a kind in one graph)."""
    return ("-r", f"__node:={prefix}_node", "-r", f"imu/attitude:={prefix}/attitude", "-r", f"imu/data:={prefix}/data",
            "-r", f"imu/rpy:={prefix}/rpy")


def wait_connected(pub, collectors, nodes, n_subs: int = 1):
    wait_matched([pub], collectors, "nodes to connect (logs: " + " | ".join(n.output() for n in nodes) + ")",
                 n_subs=n_subs)


@pytest.mark.ros
def test_ned_output_is_the_enu_output_rotated_by_c_ned(ros, start_node):
    """Two riann_nodes on the same input, ENU and NED: q_NED = C_ned ⊗ q_ENU on every output, imu/data too;
    the NED node also asks for TF, which it cannot send here (no tf2_msgs): one warning, outputs go on."""
    common = ("-p", "input_qos:=reliable", "-p", "nominal_rate:=200.0")
    enu = start_node("riann_node", *common)
    ned = start_node("riann_node", *common, *remap("ned"), "-p", "world_frame:=ned", "-p", "fixed_frame:=map",
                     "-p", "publish_tf:=true")
    pub = ros.publisher(Imu, "imu/data_raw")
    att_enu, att_ned = ros.collect(QuaternionStamped, "imu/attitude"), ros.collect(QuaternionStamped, "ned/attitude")
    imu_ned = ros.collect(Imu, "ned/data")
    wait_connected(pub, [att_enu, att_ned, imu_ned], [enu, ned], n_subs=2)
    stamps, acc, gyr = motion(150)
    send(pub, stamps, acc, gyr)
    wait_for(lambda: min(len(att_enu.messages), len(att_ned.messages), len(imu_ned.messages)) >= 150, 20,
             "outputs of both nodes")
    q_enu, q_ned = quats(att_enu.messages), quats(att_ned.messages)
    assert [stamp_ns(m) for m in att_ned.messages] == [stamp_ns(m) for m in att_enu.messages] == stamps.tolist()
    np.testing.assert_allclose(q_ned, frames.to_world(q_enu, "ned"), atol=1e-12)
    # and the ENU node is the core (the frame change did not touch the estimate)
    q_core, ok = EstimatorStream(create("riann"), GateConfig(nominal_rate=200.0)).process_batch(stamps, acc, gyr)
    assert ok.all() and np.abs(q_enu - q_core).max() < 1e-4
    o = [(m.orientation.w, m.orientation.x, m.orientation.y, m.orientation.z) for m in imu_ned.messages]
    np.testing.assert_array_equal(np.array(o), q_ned)  # imu/data carries the same world-frame orientation
    assert {m.header.frame_id for m in imu_ned.messages} == {"imu_link"}  # in the sensor frame (REP-145)
    assert {m.header.frame_id for m in att_ned.messages} == {"map"}  # fixed_frame
    assert {m.header.frame_id for m in att_enu.messages} == {"odom"}  # its default
    log = ned.output()
    assert "orientation in NED (world_frame)" in log and "world_frame=ned" in log
    assert log.count("publish_tf: tf2_msgs not available (") == 1 and "not broadcasting TF" in log
    assert "not broadcasting TF" not in enu.output()  # publish_tf defaults to false
    ros.destroy(pub, att_enu, att_ned, imu_ned)


@pytest.mark.ros
def test_level_sensor_at_rest_in_each_world_frame_on_all_four_nodes(ros, start_node):
    """Level, z-up, at rest: ENU identity, NED 180° about (x+y)/√2, NWU −90° about z, on each node type;
    imu/rpy beside each attitude topic with the attitude's header."""
    setup = {"riann": ("ned", "odom"), "madgwick": ("enu", "odom"), "mahony": ("nwu", "world"), "vqf": ("ned", "odom")}
    nodes, att, rpy = {}, {}, {}
    for name, (world, fixed) in setup.items():
        nodes[name] = start_node(f"{name}_node", "-p", "input_qos:=reliable", "-p", "nominal_rate:=200",
                                 "-p", f"world_frame:={world}", "-p", f"fixed_frame:={fixed}",
                                 "-p", "publish_rpy:=true")
        att[name] = ros.collect(QuaternionStamped, NODES[name].ATTITUDE_TOPIC)
        rpy[name] = ros.collect(Vector3Stamped, rpy_topic(NODES[name].ATTITUDE_TOPIC))
    pub = ros.publisher(Imu, "imu/data_raw")
    wait_connected(pub, [*att.values(), *rpy.values()], nodes.values(), n_subs=4)
    stamps, acc, gyr = level(100)
    send(pub, stamps, acc, gyr)
    wait_for(lambda: all(len(c.messages) >= 100 for c in [*att.values(), *rpy.values()]), 30, "outputs")
    expected = {"enu": [1.0, 0.0, 0.0, 0.0], "ned": [0.0, H, H, 0.0], "nwu": [H, 0.0, 0.0, -H]}
    expected_rpy = {"enu": [0.0, 0.0, 0.0], "ned": [180.0, 0.0, 90.0], "nwu": [0.0, 0.0, -90.0]}
    for name, (world, fixed) in setup.items():
        q = quats(att[name].messages)
        r = np.array([[m.vector.x, m.vector.y, m.vector.z] for m in rpy[name].messages])
        assert {m.header.frame_id for m in att[name].messages} == {m.header.frame_id for m in rpy[name].messages} \
            == {fixed}, name
        assert [stamp_ns(m) for m in rpy[name].messages] == stamps.tolist(), name
        np.testing.assert_allclose(r, frames.rpy_deg(q), atol=1e-9, err_msg=name)
        if name == "riann":  # the network's inclination (level within its error); heading 0 in ENU = NED yaw 90°
            r_abs = np.abs(r[-1])
            assert r_abs[0] == pytest.approx(180.0, abs=2.0) and r_abs[1] == pytest.approx(0.0, abs=2.0), r[-1]
            np.testing.assert_allclose(r[:, 2], 90.0, atol=1.0, err_msg=name)
            q_core, _ = EstimatorStream(create("riann"), GateConfig(nominal_rate=200.0)).process_batch(
                stamps, acc, gyr)
            np.testing.assert_allclose(q, frames.to_world(q_core, world), atol=1e-4)
            continue
        np.testing.assert_allclose(q, np.tile(expected[world], (100, 1)), atol=1e-6, err_msg=name)
        r_wrapped = r.copy()
        r_wrapped[:, 0] = np.where(r[:, 0] < -179.0, r[:, 0] + 360.0, r[:, 0])  # ±180° are the same roll
        np.testing.assert_allclose(r_wrapped, np.tile(expected_rpy[world], (100, 1)), atol=1e-4, err_msg=name)
    ros.destroy(pub, *att.values(), *rpy.values())


def _param_client(ros, srv_type, node_name: str, what: str):
    client = ros.node.create_client(srv_type, f"/{node_name}/{what}")
    assert client.wait_for_service(timeout_sec=15)
    return client


def _call(client, req):
    res = call_service(client, req, 10)
    assert res is not None, "no answer from the parameter service"
    return res


def _set(client, name: str, value) -> tuple[bool, str]:
    v = ParameterValue()
    if isinstance(value, str):
        v.type, v.string_value = ParameterType.PARAMETER_STRING, value
    elif isinstance(value, int):
        v.type, v.integer_value = ParameterType.PARAMETER_INTEGER, value
    else:
        v.type, v.double_value = ParameterType.PARAMETER_DOUBLE, value
    req = SetParameters.Request()
    req.parameters = [ParamMsg(name=name, value=v)]
    r = _call(client, req).results[0]
    return r.successful, r.reason


def _get(client, name: str):
    req = GetParameters.Request()
    req.names = [name]
    v = _call(client, req).values[0]
    return {ParameterType.PARAMETER_DOUBLE: ("double", v.double_value),
            ParameterType.PARAMETER_INTEGER: ("integer", v.integer_value)}.get(v.type, (v.type, None))


@pytest.mark.ros
def test_integer_values_for_float_parameters(ros, start_node, tmp_path):
    """-p nominal_rate:=200 and `diagnostics_period: 2` in a params file start the node (stored as doubles);
    a run-time int works, a string is refused with a clear reason, the ranges still hold."""
    params = tmp_path / "ints.yaml"
    params.write_text("/**:\n  ros__parameters:\n    diagnostics_period: 2\n    beta: 0\n")
    node = start_node("madgwick_node", "--params-file", str(params), "-p", "nominal_rate:=200", "-p", "max_dt:=1")
    get = _param_client(ros, GetParameters, "madgwick_node", "get_parameters")
    set_ = _param_client(ros, SetParameters, "madgwick_node", "set_parameters")
    wait_for(lambda: "parameters:" in node.output(), 10, "the start-up log")
    log = node.output()
    assert "nominal_rate=200.0" in log and "diagnostics_period=2.0" in log and "beta=0.0" in log, log
    assert _get(get, "nominal_rate") == ("double", 200.0)
    assert _get(get, "diagnostics_period") == ("double", 2.0)
    assert _set(set_, "nominal_rate", 150) == (True, "")
    assert _get(get, "nominal_rate") == ("double", 150.0)
    assert _set(set_, "beta", 1)[0] and _get(get, "beta") == ("double", 1.0)
    ok, reason = _set(set_, "nominal_rate", "fast")
    assert not ok and "DOUBLE" in reason and "STRING" in reason, reason
    assert not _set(set_, "nominal_rate", 0)[0]  # below the range, as an int too
    assert not _set(set_, "beta", 11)[0]
    assert not _set(set_, "diagnostics_period", 3)[0]  # start-up only
    assert _get(get, "nominal_rate") == ("double", 150.0)
    for c in (get, set_):
        ros.node.destroy_client(c)


@pytest.mark.ros
@pytest.mark.parametrize("args, error", [
    (("-p", "nominal_rate:=fast"), "nominal_rate must be a number, got 'fast'"),
    (("-p", "nominal_rate:=0"), "nominal_rate=0 is below its minimum 1"),
    (("-p", "world_frame:=ecef"), "world_frame must be one of enu, ned, nwu"),
])
def test_bad_start_up_values_exit_with_a_clear_error(start_node, args, error):
    node = start_node("mahony_node", *args)
    assert node.proc.wait(30) == 1
    assert f"mahony_node: error: {error}" in node.output()


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
    assert "nominal_rate" not in latest("madgwick_node").message
    set_ = _param_client(ros, SetParameters, "vqf_node", "set_parameters")
    assert _set(set_, "nominal_rate", 200) == (True, "")
    wait_for(lambda: value(latest("vqf_node"), "nominal_rate (Hz)") == "200.00", 5, "diagnostics after the set")
    assert "nominal_rate" not in latest("vqf_node").message
    ros.node.destroy_client(set_)
    ros.destroy(pub, *att, diag)
