"""The four estimator nodes side by side on one input, over real DDS, and the side-by-side launch file."""

from __future__ import annotations

import ast
import importlib.util
import os
import time

import numpy as np
import pytest
from geometry_msgs.msg import QuaternionStamped
from sensor_msgs.msg import Imu

from conftest import ROOT, rmse, wait_matched
from helpers_ros import imu_msg, publish_paced, quats, stamp_ns
from riann_ros.estimators import create
from riann_ros.evaluation import REALISTIC, scenario_recording
from riann_ros.stream import EstimatorStream, GateConfig

LAUNCH_FILE = ROOT / "launch" / "side_by_side.launch.py"
# Samples of the BROAD trial 15 realistic sequence (40,971 in all) sent through the four nodes. Four rclpy
# nodes plus the test's own rclpy receiver cost about 4 ms of CPU per input sample, so the whole sequence
# takes 90 s on 2 idle cores and about 4 min on a shared machine; the first 20,000 samples (70 s of
# motion, all scored) keep this file within ~3 min. RIANN_SIDE_BY_SIDE_SAMPLES=0 runs the whole sequence.
BROAD_SAMPLES = int(os.environ.get("RIANN_SIDE_BY_SIDE_SAMPLES", "20000"))
# estimator -> default output topics (attitude, imu); all four subscribe imu/data_raw
TOPICS = {
    "riann": ("imu/attitude", "imu/data"),
    "madgwick": ("imu/madgwick/attitude", "imu/madgwick/data"),
    "mahony": ("imu/mahony/attitude", "imu/mahony/data"),
    "vqf": ("imu/vqf/attitude", "imu/vqf/data"),
}


class Slowest:
    """len() = the fewest messages any of the collectors has: publish_paced's flow control on the slowest node."""

    def __init__(self, collectors) -> None:
        self.collectors = list(collectors)

    def __len__(self) -> int:
        return min(len(c.messages) for c in self.collectors)


def start_four(ros, start_node, *ros_args: str, per_node: dict[str, tuple[str, ...]] | None = None,
               imu_topics: bool = False):
    """Start the four executables; connect one reliable input publisher and collectors on their topics."""
    nodes = {name: start_node(f"{name}_node", *ros_args, *(per_node or {}).get(name, ())) for name in TOPICS}
    pub = ros.publisher(Imu, "imu/data_raw")
    att = {name: ros.collect(QuaternionStamped, TOPICS[name][0]) for name in TOPICS}
    imu = {name: ros.collect(Imu, TOPICS[name][1]) for name in TOPICS} if imu_topics else {}
    wait_matched([pub], [*att.values(), *imu.values()],
                 "the four nodes to connect (logs: " + " | ".join(n.output() for n in nodes.values()) + ")", n_subs=4)
    return nodes, pub, att, imu


def core(name: str, stamps, acc, gyr, rate: float, **params):
    q, ok = EstimatorStream(create(name, **params), GateConfig(nominal_rate=rate)).process_batch(stamps, acc, gyr)
    assert ok.all()
    return q


# -- launch file -------------------------------------------------------------------------------------
def test_launch_file_starts_every_node_executable_with_its_config():
    """Without launch_ros: the launch file's node list = the four console scripts, each with its YAML."""
    tree = ast.parse(LAUNCH_FILE.read_text())
    consts = {t.id: ast.literal_eval(n.value) for n in tree.body if isinstance(n, ast.Assign)
              for t in n.targets if isinstance(t, ast.Name) and t.id in ("NODES", "PACKAGE", "INPUT_TOPIC")}
    assert consts["NODES"] == tuple(TOPICS) and consts["PACKAGE"] == "riann_ros"
    assert consts["INPUT_TOPIC"] == "imu/data_raw"
    setup = (ROOT / "setup.py").read_text()
    for name in consts["NODES"]:
        assert f'"{name}_node = riann_ros.nodes.{name}_node:main"' in setup
        assert (ROOT / "config" / f"{name}.yaml").is_file()
    assert 'glob("launch/*.py")' in setup  # installed into share/riann_ros/launch
    # riann.launch.py (its arguments and the node it starts: test_package_files.py, with stand-in launch modules)
    tree = ast.parse((ROOT / "launch" / "riann.launch.py").read_text())
    consts = {t.id: ast.literal_eval(n.value) for n in tree.body if isinstance(n, ast.Assign)
              for t in n.targets if isinstance(t, ast.Name) and t.id in ("NODE", "PACKAGE", "INPUT_TOPIC")}
    assert consts == {"NODE": "riann", "PACKAGE": "riann_ros", "INPUT_TOPIC": "imu/data_raw"}


def test_launch_description_when_launch_ros_is_present(tmp_path, monkeypatch):
    pytest.importorskip("launch_ros")
    from launch.actions import DeclareLaunchArgument, OpaqueFunction

    # a minimal ament prefix so get_package_share_directory("riann_ros") finds config/ without a colcon build
    (tmp_path / "share" / "ament_index" / "resource_index" / "packages").mkdir(parents=True)
    (tmp_path / "share" / "ament_index" / "resource_index" / "packages" / "riann_ros").touch()
    (tmp_path / "share" / "riann_ros").mkdir()
    (tmp_path / "share" / "riann_ros" / "config").symlink_to(ROOT / "config")
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(tmp_path))
    spec = importlib.util.spec_from_file_location("side_by_side_launch", LAUNCH_FILE)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    ld = mod.generate_launch_description()
    args = [e for e in ld.entities if isinstance(e, DeclareLaunchArgument)]
    assert {a.name for a in args} == {"input_topic", "mag_topic", "namespace", "nominal_rate", "world_frame",
                                      "fixed_frame", "publish_tf", "publish_rpy"}
    assert len([e for e in ld.entities if isinstance(e, OpaqueFunction)]) == 1  # the four nodes


def test_riann_launch_description_when_launch_ros_is_present(tmp_path, monkeypatch):
    pytest.importorskip("launch_ros")
    from launch.actions import DeclareLaunchArgument, OpaqueFunction

    (tmp_path / "share" / "ament_index" / "resource_index" / "packages").mkdir(parents=True)
    (tmp_path / "share" / "ament_index" / "resource_index" / "packages" / "riann_ros").touch()
    (tmp_path / "share" / "riann_ros").mkdir()
    (tmp_path / "share" / "riann_ros" / "config").symlink_to(ROOT / "config")
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(tmp_path))
    spec = importlib.util.spec_from_file_location("riann_launch", ROOT / "launch" / "riann.launch.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    ld = mod.generate_launch_description()
    args = [e for e in ld.entities if isinstance(e, DeclareLaunchArgument)]
    assert {a.name for a in args} == {"params_file", "input_topic", "mag_topic", "namespace", "attitude_topic",
                                      "imu_topic", "rpy_topic", "nominal_rate", "world_frame", "fixed_frame",
                                      "publish_tf", "publish_rpy"}
    assert len([e for e in ld.entities if isinstance(e, OpaqueFunction)]) == 1


# -- four processes, one synthetic input stream --------------------------------------------------------
def synthetic(n: int, rate: float = 200.0, t0_ns: int = 1_000_000_000):
    rng = np.random.default_rng(15)
    stamps = t0_ns + (np.arange(n) * 1e9 / rate).astype(np.int64)
    acc = np.array([0.4, -0.6, 9.7]) + rng.normal(0, 0.3, (n, 3))
    gyr = rng.normal(0, 0.3, (n, 3))
    return stamps, acc, gyr


@pytest.mark.ros
def test_four_executables_each_publish_on_their_own_topics(ros, start_node):
    t0 = time.monotonic()
    nodes, pub, att, imu = start_four(ros, start_node, "-p", "input_qos:=reliable", "-p", "nominal_rate:=200.0",
                                      imu_topics=True)
    # default topics do not collide: one publisher per output topic, one input shared by the four
    for c in [*att.values(), *imu.values()]:
        assert c.sub.get_publisher_count() == 1
    assert pub.get_subscription_count() == 4
    stamps, acc, gyr = synthetic(300)
    msgs = [imu_msg(s, a, g) for s, a, g in zip(stamps, acc, gyr, strict=True)]
    publish_paced(pub, msgs, Slowest([*att.values(), *imu.values()]), len(msgs), window=50)
    time.sleep(0.3)  # nothing more may arrive
    for name, (att_topic, imu_topic) in TOPICS.items():
        got_att, got_imu = att[name].messages, imu[name].messages
        assert len(got_att) == len(got_imu) == len(msgs), (
            f"{name}: {len(got_att)} on {att_topic}, {len(got_imu)} on {imu_topic} for {len(msgs)} inputs; "
            f"log: {nodes[name].output()}")
        assert [stamp_ns(m) for m in got_att] == [stamp_ns(m) for m in got_imu] == stamps.tolist()
        q_node = quats(got_att)
        assert np.abs(q_node - core(name, stamps, acc, gyr, 200.0)).max() < 1e-4, name
        assert f"{name} estimator on '/imu/data_raw'" in nodes[name].output()
    # four different estimators, not one estimate on four topics
    finals = [quats(att[n].messages[-1:])[0] for n in TOPICS]
    assert min(np.abs(a - b).max() for i, a in enumerate(finals) for b in finals[i + 1:]) > 1e-6
    ros.destroy(pub, *att.values(), *imu.values())
    print(f"four nodes, {len(msgs)} synthetic samples: {time.monotonic() - t0:.1f} s including start-up")


# -- four processes on BROAD trial 15, realistic scenario ----------------------------------------------
@pytest.mark.ros
def test_four_nodes_on_broad_trial_15_equal_their_cores_and_riann_beats_madgwick(ros, start_node, broad_trial):
    t_start = time.monotonic()
    rec, info = scenario_recording(broad_trial("15"), REALISTIC, seed=0)
    n_all = len(rec)
    if 0 < BROAD_SAMPLES < n_all:
        rec = rec.slice(0, BROAD_SAMPLES)
    rate = rec.rate_hz
    config = {name: ("--params-file", str(ROOT / "config" / f"{name}.yaml")) for name in TOPICS}
    per_node = {name: (*config[name], "-p", "input_qos:=reliable", "-p", "input_depth:=1000",
                       "-p", f"nominal_rate:={rate!r}") for name in TOPICS}
    per_node["madgwick"] += ("-p", "beta:=0.033")
    nodes, pub, att, _ = start_four(ros, start_node, per_node=per_node)
    msgs = [imu_msg(s, a, g) for s, a, g in zip(rec.stamps_ns, rec.acc, rec.gyr, strict=True)]
    t0 = time.monotonic()
    publish_paced(pub, msgs, Slowest(att.values()), len(msgs), window=100)
    time.sleep(0.3)
    t_stream = time.monotonic() - t0
    params = {"madgwick": {"beta": 0.033}}
    errors = {}
    for name in TOPICS:
        got = att[name].messages
        assert len(got) == len(msgs), f"{name}: {len(got)} outputs for {len(msgs)} inputs; log: {nodes[name].output()}"
        assert [stamp_ns(m) for m in got] == rec.stamps_ns.tolist(), name
        q_node = quats(got)
        q_core = core(name, rec.stamps_ns, rec.acc, rec.gyr, rate, **params.get(name, {}))
        diff = np.abs(q_node - q_core).max()
        assert diff < 1e-4, f"{name}: node differs from its core by {diff}"
        errors[name] = (rmse(rec, q_node), rmse(rec, q_core))
    assert "beta=0.033" in nodes["madgwick"].output()
    ros.destroy(pub, *att.values())
    print(f"\nBROAD {rec.name}, {REALISTIC} (seed 0, from sample {info.start_index}): first {len(msgs)} of "
          f"{n_all} samples ({int(rec.score_mask.sum())} scored) at "
          f"{rate:.1f} Hz through four nodes in {t_stream:.1f} s ({len(msgs) / t_stream:.0f} samples/s), "
          f"{time.monotonic() - t_start:.1f} s in all")
    for name, (e_node, e_core) in errors.items():
        print(f"  {name:9s} inclination RMSE node {e_node:.3f}°  core {e_core:.3f}°")
    assert errors["riann"][0] < errors["madgwick"][0]
