"""The node's outputs (riann_ros.nodes.outputs): the orientation in the chosen world frame, fixed_frame, imu/rpy
beside each attitude topic, the TF message.

The pure parts (the TF message, the rpy topic names) are tested in-process, the rest over real DDS with the node
executables.
"""

from __future__ import annotations

import time

import numpy as np
import pytest
from geometry_msgs.msg import QuaternionStamped, Vector3Stamped
from sensor_msgs.msg import Imu

from conftest import wait_for, wait_matched
from helpers_ros import imu_msg, quats, stamp_ns
from riann_ros import frames
from riann_ros.estimators import create
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


