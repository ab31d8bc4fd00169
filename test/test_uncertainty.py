"""The per-sample uncertainty the estimators report (AttitudeEstimator.sigma): RIANN's model (stage 8) against the
documented constants of the classical filters, batch equal to per sample, and the σ never feeding back."""

from __future__ import annotations

import math

import numpy as np
import pytest

from riann_ros.defaults import INCLINATION_SD_DEG, MAG_HEADING_SD_DEG, YAW_FREE_SD_DEG
from riann_ros.estimators import create
from riann_ros.estimators.riann.estimator import RiannEstimator
from riann_ros.estimators.riann.s8_uncertainty import inclination_sigma

RATE = 200.0


def _motion(n: int, seed: int = 3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.arange(n) / RATE
    gyr = np.column_stack([np.sin(t), 0.5 * np.cos(2 * t), 0.3 * np.sin(0.5 * t)]) * (t > n / RATE / 2)[:, None]
    gyr += rng.normal(0, 0.01, (n, 3))
    acc = np.array([0.0, 0.0, 9.81]) + rng.normal(0, 0.05, (n, 3))
    return acc, gyr, np.full(n, 1.0 / RATE)


@pytest.mark.parametrize("name", ["madgwick", "mahony", "vqf"])
def test_classical_filters_report_their_documented_constants(name):
    est = create(name)
    acc, gyr, dt = _motion(20)
    mag = np.tile([0.0, 2e-5, -4e-5], (20, 1))
    mag[:10] = np.nan
    est.update_batch(acc, gyr, dt, mag)
    s = np.degrees(est.sigma(np.isfinite(mag).all(axis=1)))
    assert np.allclose(s[:, 0], INCLINATION_SD_DEG)
    assert np.allclose(s[:10, 1], YAW_FREE_SD_DEG) and np.allclose(s[10:, 1], MAG_HEADING_SD_DEG)


def test_riann_sigma_batch_equals_per_sample_and_grows_with_the_copies_spread():
    n = 1200
    acc, gyr, dt = _motion(n)
    est = RiannEstimator()
    q_b = est.update_batch(acc, gyr, dt)
    s_b = est.sigma(np.zeros(n, dtype=bool))
    with pytest.raises(ValueError, match="last call"):
        est.sigma(np.zeros(3, dtype=bool))
    one = RiannEstimator(model=est.model)
    s_1 = []
    for i in range(n):
        one.update(acc[i], gyr[i], dt[i])
        s_1.append(one.sigma(np.zeros(1, dtype=bool))[0])
    assert np.abs(np.array(s_1) - s_b).max() < 1e-6
    assert (s_b > 0).all() and np.allclose(s_b[:, 1], math.radians(YAW_FREE_SD_DEG))
    # at turn-on the bias is unknown (σ_b = bias_sigma_init): larger than after it has settled at rest
    assert s_b[0, 0] > 2.0 * s_b[n // 2 - 1, 0]
    f = est.uncertainty.features
    more = f.copy()
    more[:, 0] *= 2.0
    assert (inclination_sigma(more) > inclination_sigma(f)).all()
    assert q_b.shape == (n, 4)


def test_riann_sigma_never_changes_the_attitude():
    """The attitude with stage 8 equals the attitude with its output ignored (it only reads): run twice, once
    asking for σ after every sample, once never."""
    n = 600
    acc, gyr, dt = _motion(n, seed=5)
    a = RiannEstimator()
    b = RiannEstimator(model=a.model)
    q_a = np.array([a.update(acc[i], gyr[i], dt[i]) for i in range(n)])
    q_b = []
    for i in range(n):
        q_b.append(b.update(acc[i], gyr[i], dt[i]))
        b.sigma(np.zeros(1, dtype=bool))
    assert np.abs(q_a - np.array(q_b)).max() == 0.0
