"""riann_ros/estimators/bias.py: the gyro-bias front end (VQF's bias estimation) learns a turn-on bias."""

from __future__ import annotations

import numpy as np
from helpers_riann import tilted_rest

from riann_ros.estimators.bias import GyroBiasFrontEnd


def test_bias_front_end_learns_a_3_deg_s_turn_on_bias_at_rest():
    n = 200 * 10
    acc, _ = tilted_rest(n)
    bias = np.radians([3.0, -3.0, 1.0])
    fe = GyroBiasFrontEnd(0.005)
    before = fe.update_batch(acc, np.tile(bias, (n, 1)))
    assert np.all(before[0] == 0.0)  # nothing is known before the first sample
    assert np.abs(np.degrees(fe.bias) - [3.0, -3.0, 1.0]).max() < 0.2
    # per sample gives the same estimates
    fe2 = GyroBiasFrontEnd(0.005)
    for i in range(n):
        assert np.allclose(fe2.bias, before[i], atol=1e-12)
        fe2.update(acc[i], bias)
    # a new sample time keeps what was learned
    fe2.set_ts(0.01)
    assert np.allclose(fe2.bias, fe.bias, atol=1e-12)


def test_default_vqf_clip_would_not_learn_the_3_deg_s_bias():
    n = 200 * 10
    acc, _ = tilted_rest(n)
    fe = GyroBiasFrontEnd(0.005, clip=2.0, sigma_init=0.5)
    fe.update_batch(acc, np.tile(np.radians([3.0, -3.0, 1.0]), (n, 1)))
    assert np.abs(np.degrees(fe.bias)).max() <= 2.0 + 1e-9
