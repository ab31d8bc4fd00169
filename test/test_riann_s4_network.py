"""riann_ros/estimators/riann/s4_network.py: the copies combined per row, a fresh state from each fork."""

from __future__ import annotations

import numpy as np
import onnxruntime as ort
import pytest
from helpers_riann import hole_stream, swinging_stream

from conftest import gate_dts
from riann_ros import quaternion as quat
from riann_ros.estimators import create
from riann_ros.estimators.riann import default_model_path
from riann_ros.estimators.riann.s4_network import Network
from riann_ros.estimators.riann.s4a_ensemble import combine, frames, rotate_rows
from riann_ros.estimators.riann.s4b_model import BatchedModel
from riann_ros.estimators.riann.stage import BiasBlock, Cause, GridBlock, NetworkIn


@pytest.fixture(scope="module")
def model():
    return BatchedModel(copies=4)


def _rows(rows: list, forks: list[int]) -> NetworkIn:
    """Network rows (acc, gyr, dt) and where fresh states start, as stages 2 and 3 give them."""
    n = len(rows)
    grid = GridBlock([r[:6] for r in rows], [r[6] for r in rows], forks, [], [], [], [], [], [], [])
    return NetworkIn(grid, BiasBlock(rows, [(0.0, 0.0, 0.0)] * (n + 1), [0.0] * (n + 1)))


def test_network_block_equals_rows_across_a_fork(model):
    """A fork at row 120: that row is the old state's output, a fresh state starts on it and outputs from the next
    row on; the same whether the fork comes with row 120, after row 119 (the end of the block before), or in a
    block of every row."""
    x, _ = swinging_stream(300, jitter=False)
    rows = [(*r, 0.005) for r in x]
    whole = Network(model).run(_rows(rows, [120]))
    assert whole.q.shape == (300, 4) and whole.spread_rad.shape == (300,)
    for at_end in (False, True):
        net = Network(model)
        one = [net.run(_rows(rows[k:k + 1], [1] if at_end and k == 119 else [0] if not at_end and k == 120 else []))
               for k in range(len(rows))]
        assert np.abs(np.vstack([o.q for o in one]) - whole.q).max() < 1e-6
        assert np.abs(np.concatenate([o.spread_rad for o in one]) - whole.spread_rad).max() < 1e-6
        assert net.holes == 1 and net.rows == 300
    plain = Network(model).run(_rows(rows, [])).q
    assert np.abs(whole.q[:121] - plain[:121]).max() < 1e-6  # the fork row: still the old state's
    fresh = Network(model).run(_rows(rows[120:], [])).q
    assert np.abs(whole.q[121:] - fresh[1:]).max() < 1e-6  # then the fresh state, which started on the fork row
    assert np.abs(whole.q[121:131] - plain[121:131]).max() > 1e-3


def test_a_fork_at_the_end_of_the_stream_waits_for_the_next_row_and_a_gap_drops_it(model):
    x, _ = swinging_stream(40, jitter=False)
    rows = [(*r, 0.005) for r in x]
    a = Network(model)
    a.run(_rows(rows[:20], [20]))
    a.restart(Cause.GAP)
    b = Network(model)
    b.run(_rows(rows[:20], []))
    b.restart(Cause.GAP)
    assert np.array_equal(a.run(_rows(rows[20:], [])).q, b.run(_rows(rows[20:], [])).q)


@pytest.mark.slow
def test_after_a_hole_a_fresh_network_takes_over_and_converges_faster():
    est, t, err = hole_stream(0.1)
    assert est.network.holes == 1
    _, _, err0 = hole_stream(0.0)
    late = (t > 1.5) & (t < 2.5)
    assert err[late].max() < 5.0, err[late].max()
    assert err[late].mean() < 0.5 * err0[late].mean(), (err[late].mean(), err0[late].mean())


@pytest.mark.slow
def test_a_clean_stream_in_the_trained_range_gives_the_network_inclination(broad_trial):
    """At 285.7 Hz the grid rows are the samples: without the bias front end the output's inclination
    is the network's own (the heading stage only replaces its yaw)."""
    rec = broad_trial("07")
    sess = ort.InferenceSession(str(default_model_path()))
    x = np.column_stack([rec.acc, rec.gyr, gate_dts(rec)]).astype(np.float32)[None]
    out, _ = sess.run(None, {"input": x, "h0": np.zeros((2, 1, 1, 200), np.float32)})
    est = create("riann", gyro_bias_estimation=False, ensemble=1)
    q = est.update_batch(rec.acc, rec.gyr, gate_dts(rec))
    assert est.network.rows == len(rec)
    ref = out[0] / np.linalg.norm(out[0], axis=1, keepdims=True)
    assert np.degrees(quat.inclination_error(ref, q)).max() < 1e-3
    # the heading is not the network's: it starts at zero (no rotation about world z)
    assert abs(2 * np.arctan2(q[0, 3], q[0, 0])) < 1e-9


@pytest.mark.slow
def test_estimator_output_is_the_four_network_copies_combined(broad_trial):
    """At 285.7 Hz the grid rows are the samples: without the bias front end the output's inclination is the
    combination of the official network run directly on the four turned copies of the IMU."""
    rec = broad_trial("07").slice(0, 6000)
    sess = ort.InferenceSession(str(default_model_path()))
    rows = np.column_stack([rec.acc, rec.gyr, gate_dts(rec)])
    outs = []
    for r in frames(4):
        x = rotate_rows(rows, r).astype(np.float32)[None]
        out, _ = sess.run(None, {"input": x, "h0": np.zeros((2, 1, 1, 200), np.float32)})
        outs.append(out[0] / np.linalg.norm(out[0], axis=1, keepdims=True))
    ref = combine(outs, frames(4))[0]
    est = create("riann", gyro_bias_estimation=False)
    q = est.update_batch(rec.acc, rec.gyr, gate_dts(rec))
    assert np.degrees(quat.inclination_error(ref, q)).max() < 1e-3
    # the copies disagree (else there would be nothing to average): copy 0 alone is not the ensemble
    assert np.degrees(quat.inclination_error(outs[0], ref)).max() > 0.1
