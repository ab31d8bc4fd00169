"""riann_ros/estimators/riann/s3_bias.py: the bias front end on the rows, a block equal to its rows, and the output
without drift under a turn-on bias."""

from __future__ import annotations

import numpy as np
import pytest
from helpers_riann import swinging_stream, tilted_rest

from riann_ros import quaternion as quat
from riann_ros.estimators.riann import RiannEstimator
from riann_ros.estimators.riann.s3_bias import BATCH_ROWS, Bias
from riann_ros.estimators.riann.stage import GridBlock


def test_bias_block_equals_rows():
    x, _ = swinging_stream(600, jitter=False)
    rows = [(*r[:3], r[3] + 0.05, r[4] - 0.03, r[5]) for r in x]
    steps = [0.005] * 300 + [0.004] * 300  # a grid-step switch in the block
    whole = Bias(True, 8.0, 3.0).run(_rows(rows, steps))
    one = Bias(True, 8.0, 3.0)
    got = [one.run(_rows([r], [s])) for r, s in zip(rows, steps, strict=True)]
    assert len(rows) >= BATCH_ROWS
    assert np.allclose([g.rows[0] for g in got], whole.rows, atol=1e-12)
    assert np.allclose([g.bias_rad_s[0] for g in got], whole.bias_rad_s[:-1], atol=1e-12)
    assert np.allclose([g.sigma_rad_s[0] for g in got], whole.sigma_rad_s[:-1], atol=1e-15)
    assert np.abs(np.array(whole.bias_rad_s[-1])).max() > 0.0  # it learned something
    assert whole.sigma_rad_s[-1] < whole.sigma_rad_s[0]  # and knows it better


def test_off_the_bias_is_zero_and_its_sigma_zero():
    x, _ = swinging_stream(20, jitter=False)
    b = Bias(False, 8.0, 3.0).run(_rows(x, [0.005] * 20))
    assert b.bias_rad_s == [(0.0, 0.0, 0.0)] * 21 and b.sigma_rad_s == [0.0] * 21
    assert [r[3:6] for r in b.rows] == [tuple(r[3:6]) for r in x]


def _rows(rows: list, steps: list[float]) -> GridBlock:
    """A grid block of just these rows (what stage 3 reads of it)."""
    n = len(rows)
    return GridBlock(rows, steps, [], [0] * n, [0] * n, [(0.0, 0.0, 0.0)] * n, [0.0] * n, [(0.0, 0.0, 0.0)] * n,
                     [0.0] * n, [])


@pytest.mark.slow
def test_riann_with_the_front_end_does_not_drift_with_a_gyro_bias():
    n = 200 * 60
    acc, q_true = tilted_rest(n)
    gyr = np.tile(np.radians([3.0, 3.0, 0.0]), (n, 1))
    dt = np.full(n, 0.005)
    with_fe = RiannEstimator().update_batch(acc, gyr, dt)
    without = RiannEstimator(gyro_bias_estimation=False).update_batch(acc, gyr, dt)
    err_with = np.degrees(quat.inclination_error(q_true, with_fe[-2000:])).max()
    err_without = np.degrees(quat.inclination_error(q_true, without[-2000:])).max()
    assert err_with < 1.0, err_with
    assert err_without > 2 * err_with, (err_with, err_without)
    est = RiannEstimator()
    est.update_batch(acc, gyr, dt)
    assert "gyro bias estimate (deg/s)" in est.diagnostics()
