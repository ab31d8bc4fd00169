"""consensus_node over real DDS: one output per input, equal to the offline consensus (the evaluator's path) through a
hole, imu/data's covariance its σ, and its diagnostics."""

from __future__ import annotations

import time

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import QuaternionStamped
from sensor_msgs.msg import Imu

from conftest import wait_for, wait_matched
from helpers_ros import imu_msg, publish_paced, quats, stamp_ns
from riann_ros.datasets.synthetic import generate
from riann_ros.estimators import create
from riann_ros.nodes.consensus_node import ConsensusNode
from riann_ros.stream import EstimatorStream, GateConfig

pytestmark = pytest.mark.ros


def test_consensus_node_equals_offline_through_a_hole(ros, start_node):
    rec = generate(duration=15.0, rate=200.0, seed=4, bias=0.04)
    keep = np.ones(len(rec.acc), dtype=bool)
    keep[1600:1660] = False  # 0.3 s lost at 8 s: a hole the grid bridges, RIANN hands over, VQF restarts
    stamps = rec.stamps_ns[keep] + 1_700_000_000_000_000_000
    acc, gyr = rec.acc[keep], rec.gyr[keep]
    node = start_node("consensus_node", "-p", "input_qos:=reliable", "-p", "nominal_rate:=200.0",
                      "-p", "diagnostics_period:=0.5")
    pub = ros.publisher(Imu, "imu/data_raw", reliable=True)
    att = ros.collect(QuaternionStamped, ConsensusNode.ATTITUDE_TOPIC)
    imu_out = ros.collect(Imu, ConsensusNode.IMU_TOPIC)
    diag = ros.collect(DiagnosticArray, "/diagnostics")
    wait_matched([pub], [att, imu_out], f"consensus_node to connect (log: {node.output()})")
    msgs = [imu_msg(s, a, g) for s, a, g in zip(stamps, acc, gyr, strict=True)]
    t0 = time.monotonic()
    try:
        publish_paced(pub, msgs, att.messages, len(msgs))
    except AssertionError as e:
        raise AssertionError(f"{e}; node log: {node.output()[-3000:]}") from None
    print(f"{len(msgs)} messages through consensus_node in {time.monotonic() - t0:.1f} s")
    got = att.messages
    assert len(got) == len(msgs) and [stamp_ns(m) for m in got] == stamps.tolist()
    core = EstimatorStream(create("consensus"), GateConfig(nominal_rate=200.0))
    q_core, ok = core.process_batch(stamps, acc, gyr)
    assert ok.all()
    assert np.abs(quats(got) - q_core).max() < 1e-4
    wait_for(lambda: len(imu_out.messages) >= len(msgs), 30, "imu/data")
    cov = np.array([m.orientation_covariance for m in imu_out.messages])
    np.testing.assert_allclose(cov[:, 0], core.batch_sigma[:, 0] ** 2, rtol=1e-3, atol=1e-9)
    np.testing.assert_allclose(cov[:, 4], cov[:, 0])
    def weight_reported() -> bool:
        return any(s.name.startswith("consensus_node:") and any(v.key == "consensus weight on RIANN" for v in s.values)
                   for d in diag.messages for s in d.status)

    wait_for(weight_reported, 10, f"the consensus's diagnostics ({[s.name for d in diag.messages for s in d.status]})")
    ros.destroy(pub, att, imu_out, diag)
