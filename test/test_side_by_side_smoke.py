"""The four estimator nodes side by side, end to end over real DDS: the four executables on one input stream, each
publishing on its own topics and equal to its core; on BROAD trial 15 RIANN beats Madgwick."""

from __future__ import annotations

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
