"""Faults the way ROS users cause them, on the installed node executables over real DDS: a driver that stops and
restarts, a bag replayed in a loop with /clock, bursts, best-effort and reliable drivers at once, a node killed and
restarted.

The tests talk to the nodes through the test-side rclpy node (``ros`` fixture); nothing of ROS is mocked. Every node
output is compared with what :class:`riann_ros.stream.EstimatorStream` gives offline on the same stamp sequence, so
"no output with a wrong dt" is checked sample by sample, not just "something came out".
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from geometry_msgs.msg import QuaternionStamped
from sensor_msgs.msg import Imu

from conftest import ROOT, wait_for, wait_matched
from helpers_ros import imu_msg, publish_paced, quats, stamp_ns
from riann_ros import bagio
from riann_ros.datasets.synthetic import generate
from riann_ros.estimators import create
from riann_ros.stream import EstimatorStream, GateConfig

NS = 1_000_000_000
T0 = 1_700_000_000 * NS  # a plausible wall-clock stamp (a zero stamp means "unstamped")
TOL = 1e-4  # node (per message) vs EstimatorStream.process_batch, as in test_nodes_node_base.py

ros = pytest.mark.ros


# ---- helpers --------------------------------------------------------------------------------------


def motion(n: int, rate: float = 200.0, seed: int = 0, t0_ns: int = T0):
    """n samples of the synthetic generator's smooth motion, stamped from t0_ns."""
    rec = generate(rate=rate, duration=(n + 1) / rate, seed=seed)
    return rec.stamps_ns[:n] + t0_ns, rec.acc[:n], rec.gyr[:n]


def expected(stamps, acc, gyr, rate: float = 200.0, name: str = "riann", max_dt: float = 0.5):
    return EstimatorStream(create(name), GateConfig(nominal_rate=rate, max_dt=max_dt)).process_batch(stamps, acc, gyr)


def connect(ros_h, node, topic: str = "imu/attitude", reliable_in: bool = True):
    pub = ros_h.publisher(Imu, "imu/data_raw", reliable=reliable_in)
    att = ros_h.collect(QuaternionStamped, topic)
    wait_matched([pub], [att], f"node to connect (log: {node.output()})")
    return pub, att


def check_against_core(got, stamps, acc, gyr, rate=200.0):
    """The node's outputs are exactly the accepted samples of EstimatorStream, in order, same numbers."""
    q_core, ok = expected(stamps, acc, gyr, rate)
    assert [stamp_ns(m) for m in got] == stamps[ok].tolist()
    q = quats(got)
    assert np.isfinite(q).all() and np.allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-6)
    assert np.abs(q - q_core[ok]).max() < TOL
    return ok


# A driver in a process of its own: publishes samples from an .npz file on imu/data_raw (reliable),
# paced, after its subscriber matched; waits until everything is acknowledged, then exits.
DRIVER = r"""
import sys, time
import numpy as np
import rclpy
from rclpy.duration import Duration
from rclpy.qos import QoSProfile, ReliabilityPolicy, HistoryPolicy
from sensor_msgs.msg import Imu
from riann_ros import stamps
d = np.load(sys.argv[1]); period = float(sys.argv[2])
rclpy.init()
node = rclpy.create_node("fake_imu_driver")
pub = node.create_publisher(Imu, "imu/data_raw", QoSProfile(depth=10000, history=HistoryPolicy.KEEP_LAST,
                                                            reliability=ReliabilityPolicy.RELIABLE))
end = time.monotonic() + 20
while pub.get_subscription_count() == 0 and time.monotonic() < end:
    time.sleep(0.01)
time.sleep(1.0)  # the node's side of the match (conftest.MATCH_GRACE_S)
for s, a, g in zip(d["stamps"], d["acc"], d["gyr"]):
    m = Imu()
    stamps.set_ns(m.header.stamp, s)
    m.header.frame_id = "imu_link"
    m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z = (float(v) for v in a)
    m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z = (float(v) for v in g)
    pub.publish(m)
    time.sleep(period)
ok = pub.wait_for_all_acked(Duration(seconds=10))
node.destroy_node()
rclpy.shutdown()
print("driver done", len(d["stamps"]), "acked" if ok else "NOT ACKED", flush=True)
"""


def run_driver(tmp_path: Path, k: int, stamps, acc, gyr, period: float = 0.003) -> None:
    f = tmp_path / f"driver{k}.npz"
    np.savez(f, stamps=np.asarray(stamps, dtype=np.int64), acc=acc, gyr=gyr)
    r = subprocess.run([sys.executable, "-c", DRIVER, str(f), str(period)], capture_output=True, text=True,
                       timeout=60, env=os.environ.copy())
    assert r.returncode == 0 and "acked" in r.stdout and "NOT" not in r.stdout, r.stdout + r.stderr


def settle(att, n_expected: int, timeout: float = 20.0) -> None:
    wait_for(lambda: len(att.messages) >= n_expected, timeout, f"{n_expected} outputs (have {len(att.messages)})")
    time.sleep(0.3)  # nothing more must come


# ---- the driver stops and restarts ------------------------------------------------------------------


@ros
def test_driver_restarts_node_resumes_and_restarts_where_stamps_say(ros, start_node, tmp_path):
    node = start_node("riann_node", "-p", "input_qos:=reliable", "-p", "nominal_rate:=200.0", "-p", "max_dt:=0.5")
    att = ros.collect(QuaternionStamped, "imu/attitude")
    wait_matched([], [att], f"node (log: {node.output()})")
    s, a, g = motion(800)
    # driver 1: samples 0..199; driver 2 (new process, after a pause): stamps continue, 200..399;
    # driver 3: restarts its clock 3 s back (> max_dt: restart); driver 4: resumes 0.1 s before
    # driver 3's last stamp (≤ max_dt back: those samples are rejected as out of order, then it goes on).
    seg = [
        (s[0:200], a[0:200], g[0:200]),
        (s[200:400], a[200:400], g[200:400]),
        (s[400:600] - 3 * NS - (s[400] - s[0]), a[400:600], g[400:600]),
    ]
    last3 = int(seg[2][0][-1])
    d4 = s[600:800] - s[600] + last3 - 100_000_000  # 20 samples at or before last3 (5 ms grid), 180 after
    seg.append((d4, a[600:800], g[600:800]))
    for k, (ss, aa, gg) in enumerate(seg):
        run_driver(tmp_path, k, ss, aa, gg)
        time.sleep(0.5)  # the driver is gone for a while
    stamps = np.concatenate([x[0] for x in seg])
    _, ok = expected(stamps, a, g)
    assert (~ok).sum() == 21  # 20 out of order + 1 repeat of last3
    settle(att, int(ok.sum()))
    check_against_core(att.messages, stamps, a, g)
    log = node.output()
    assert log.count("clock jump at stamp") == 1 and "gap at stamp" not in log
    assert "stamp_backwards" in log
    # the restart really restarted: a fresh estimator from driver 3's first sample gives the same numbers
    q3 = create("riann").update_batch(seg[2][1], seg[2][2], np.r_[1 / 200.0, np.diff(seg[2][0]) * 1e-9])
    assert np.abs(quats(att.messages[400:600]) - q3).max() < TOL
    assert node.proc.poll() is None
    ros.destroy(att)


# ---- a bag replayed in a loop with /clock ------------------------------------------------------------


@ros
def test_bag_loop_with_sim_time_second_pass_equals_first(ros, start_node):
    from rosgraph_msgs.msg import Clock

    rec = bagio.read_recording(ROOT / "bags" / "synthetic_rotation_100hz.mcap")
    sl = slice(1, 301)  # skip the zero stamp the bag starts with (it would mean "unstamped")
    stamps, acc, gyr = rec.stamps_ns[sl], rec.acc[sl], rec.gyr[sl]
    node = start_node("riann_node", "-p", "use_sim_time:=true", "-p", "input_qos:=reliable",
                      "-p", "nominal_rate:=100.0")
    pub, att = connect(ros, node)
    clock = ros.publisher(Clock, "/clock", reliable=True, depth=10)
    wait_matched([clock], [], "node's /clock subscription")
    msgs = [imu_msg(x, y, z) for x, y, z in zip(stamps, acc, gyr, strict=True)]
    n = len(msgs)
    for p in range(2):  # what `ros2 bag play --loop --clock` does: the clock goes back with every loop
        for m in msgs:
            c = Clock()
            c.clock = m.header.stamp
            clock.publish(c)
            pub.publish(m)
            time.sleep(0.002)
        settle(att, (p + 1) * n)
    got = att.messages
    assert len(got) == 2 * n
    assert [stamp_ns(m) for m in got] == stamps.tolist() * 2
    q = quats(got)
    assert np.abs(q[:n] - q[n:]).max() < 1e-6
    q_core, ok = expected(np.r_[stamps, stamps], np.r_[acc, acc], np.r_[gyr, gyr], rate=100.0)
    assert ok.all() and np.abs(q - q_core).max() < TOL
    assert node.output().count("clock jump at stamp") == 1
    time.sleep(1.5)  # the node (its timers run on the jumped-back ROS clock) is still alive
    assert node.proc.poll() is None, node.output()
    ros.destroy(pub, att, clock)


# ---- bursts -----------------------------------------------------------------------------------------


@ros
def test_burst_of_500_after_a_pause_is_processed_whole_and_in_order(ros, start_node):
    node = start_node("riann_node", "-p", "nominal_rate:=200.0")  # default QoS: sensor_data, depth 1000
    pub, att = connect(ros, node)
    s, a, g = motion(550)
    msgs = [imu_msg(x, y, z) for x, y, z in zip(s, a, g, strict=True)]
    # Best effort: messages sent before the node's reader has matched this writer are lost. Prime
    # until one gets through (stamped 10 s later, so the real stream starts with a clock-jump reset,
    # exactly like a fresh estimator; a gap would keep RIANN's bias estimate), then forget the priming
    # output.
    prime = imu_msg(s[0] + 10_000_000_000, a[0], g[0])
    wait_for(lambda: pub.publish(prime) or time.sleep(0.05) or len(att.messages) > 0, 20, "a first output")
    time.sleep(0.3)
    att.messages.clear()
    publish_paced(pub, msgs[:50], att.messages, 50)
    settle(att, 50)
    time.sleep(1.0)  # the pause
    for m in msgs[50:]:  # 500 at once
        pub.publish(m)
    settle(att, 550, timeout=30)
    assert len(att.messages) == 550
    check_against_core(att.messages, s, a, g)
    assert "input_depth=1000" in node.output()
    ros.destroy(pub, att)


@ros
def test_burst_larger_than_input_depth_loses_oldest_never_reorders(ros, start_node):
    """Documented policy: keep-last input_depth; a larger burst loses messages in DDS, never reorders."""
    node = start_node("riann_node", "-p", "nominal_rate:=200.0", "-p", "input_depth:=20")
    pub, att = connect(ros, node)
    s, a, g = motion(3000)
    msgs = [imu_msg(x, y, z) for x, y, z in zip(s, a, g, strict=True)]
    time.sleep(0.5)
    for m in msgs:
        pub.publish(m)
    wait_for(lambda: att.messages and stamp_ns(att.messages[-1]) == s[-1], 30, "the newest message")
    time.sleep(0.5)
    got = att.messages
    st = np.array([stamp_ns(m) for m in got])
    assert (np.diff(st) > 0).all()  # never reordered
    assert len(got) <= len(msgs)
    idx = np.searchsorted(s, st)
    assert (s[idx] == st).all()
    # what arrived is processed exactly as EstimatorStream processes that subsequence (dt from stamps)
    check_against_core(got, s[idx], a[idx], g[idx])
    print(f"burst of {len(msgs)} with input_depth 20: {len(got)} processed, {len(msgs) - len(got)} lost")
    ros.destroy(pub, att)


# ---- best effort and reliable drivers at the same time ---------------------------------------------


@ros
def test_best_effort_and_reliable_publishers_at_once(ros, start_node):
    node = start_node("riann_node", "-p", "nominal_rate:=200.0")  # default settings
    pub_be = ros.publisher(Imu, "imu/data_raw", reliable=False)
    pub_rel = ros.publisher(Imu, "imu/data_raw", reliable=True)
    att = ros.collect(QuaternionStamped, "imu/attitude")
    imu_out = ros.collect(Imu, "imu/data")  # keeps the input's frame_id (imu/attitude carries fixed_frame)
    wait_matched([pub_be, pub_rel], [att, imu_out], f"both publishers to connect (log: {node.output()})")
    s, a, g = motion(200)
    for k in range(4):  # alternate blocks of 50: best effort, reliable, best effort, reliable
        pub, frame = (pub_be, "driver_be") if k % 2 == 0 else (pub_rel, "driver_rel")
        for i in range(50 * k, 50 * (k + 1)):
            pub.publish(imu_msg(s[i], a[i], g[i], frame_id=frame))
            time.sleep(0.003)
    settle(att, 200)
    settle(imu_out, 200)
    got = att.messages
    frames = [m.header.frame_id for m in imu_out.messages]
    assert frames.count("driver_rel") == 100 and frames.count("driver_be") == 100
    check_against_core(got, s, a, g)
    ros.destroy(pub_be, pub_rel, att, imu_out)


# ---- node killed and restarted ---------------------------------------------------------------------


def _gids(infos) -> set[bytes]:
    return {bytes(i.endpoint_gid) for i in infos}


@ros
def test_node_killed_and_restarted_reinitialises_from_next_sample(ros, start_node):
    args = ("-p", "input_qos:=reliable", "-p", "nominal_rate:=200.0")
    node = start_node("riann_node", *args)
    pub, att = connect(ros, node)
    s, a, g = motion(400)
    msgs = [imu_msg(x, y, z) for x, y, z in zip(s, a, g, strict=True)]
    publish_paced(pub, msgs[:200], att.messages, 200)
    settle(att, 200)
    check_against_core(att.messages, s[:200], a[:200], g[:200])
    old_sub = _gids(ros.node.get_subscriptions_info_by_topic("/imu/data_raw"))
    old_pub = _gids(ros.node.get_publishers_info_by_topic("/imu/attitude"))
    node.proc.send_signal(signal.SIGKILL)
    node.proc.wait(10)
    node2 = start_node("riann_node", *args)
    wait_for(lambda: _gids(ros.node.get_subscriptions_info_by_topic("/imu/data_raw")) - old_sub
             and _gids(ros.node.get_publishers_info_by_topic("/imu/attitude")) - old_pub, 20,
             f"restarted node in the graph (log: {node2.output()})")
    time.sleep(1.0)  # endpoint matching
    before = len(att.messages)
    for m in msgs[200:]:
        pub.publish(m)
        time.sleep(0.003)
    settle(att, before + 200)
    after = att.messages[before:]
    assert len(after) == 200
    assert [stamp_ns(m) for m in after] == s[200:].tolist()
    # a fresh estimator from the first sample after the restart, first dt = 1/nominal_rate
    q_fresh = create("riann").update_batch(a[200:], g[200:], np.r_[1 / 200.0, np.diff(s[200:]) * 1e-9])
    assert np.abs(quats(after) - q_fresh).max() < TOL
    log = node2.output()
    assert "Traceback" not in log and "error" not in log.lower(), log
    ros.destroy(pub, att)
    # the killed node said no goodbye: its endpoints stay in the graph until its DDS lease runs out; the next test
    # must not count them as a second publisher
    wait_for(lambda: not _gids(ros.node.get_publishers_info_by_topic("/imu/attitude")) & old_pub, 60,
             "the killed node's endpoints to leave the graph")
