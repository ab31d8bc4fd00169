"""The ROS side of riann-bag-eval --live (riann_ros.ros.dds_replay): a real madgwick_node started by the replay, a
recording sent over DDS in two pieces, typed records back — the node's estimate at every sample, equal to the same
estimator run in-process, its covariance, the counts; a second sequence starts the estimator afresh."""

from __future__ import annotations

import numpy as np
import pytest
from test_evaluation import synthetic

from riann_ros.estimators import create
from riann_ros.gate import GateConfig
from riann_ros.magcal.input import MagConfig
from riann_ros.replay import NodeSpec
from riann_ros.ros.dds_replay import DdsReplay
from riann_ros.stream import EstimatorStream

RATE = 100.0
BETA = 0.1


@pytest.mark.ros
@pytest.mark.slow
def test_a_sequence_sent_in_pieces_comes_back_as_the_in_process_estimates(tmp_path):
    rec = synthetic(rate=RATE, rest_s=1.0, move_s=3.0, t0_ns=5_000_000_000)
    half = len(rec) // 2
    offline = EstimatorStream(create("madgwick", beta=BETA), GateConfig.for_rate(RATE), MagConfig(use_mag="false"))
    want, _ = offline.process_batch(rec.stamps_ns, rec.acc, rec.gyr, None)
    with_replay = DdsReplay(speed=0.0, log_dir=tmp_path, use_mag="false")
    try:
        for _ in range(2):  # the second sequence: the node restarted, the same estimates again
            seq = with_replay.sequence([NodeSpec("madgwick", (("beta", BETA),))], RATE)
            pieces = [seq.send(rec.slice(0, half)), seq.send(rec.slice(half))]
            counts = seq.end()
            rows = np.vstack([p.rows[0] for p in pieces])
            assert rows.shape == (len(rec), 7) and [p.unexpected for p in pieces] == [[0], [0]]
            np.testing.assert_allclose(rows[:, :4], want, atol=1e-9)
            assert np.isfinite(rows[:, 4:]).all()  # the covariance of the node's imu output
            assert counts.published == len(rec) and counts.mag_samples == 0 and counts.reads_mag == [False]
    finally:
        with_replay.close()
    assert list(tmp_path.glob("node_0_madgwick.log"))
