"""The synthetic generator: exact ground truth, consistent gyroscope and specific force."""

from __future__ import annotations

import numpy as np
import pytest

from riann_ros import quaternion as quat
from riann_ros.constants import GRAVITY
from riann_ros.datasets.synthetic import MOTIONS, generate, integrate_gyr


@pytest.mark.parametrize("motion", MOTIONS)
def test_gyro_integrates_to_truth(motion: str) -> None:
    """Documented tolerance: noise-free, bias-free gyr integrated (trapezoid) stays within 0.1° at 200 Hz."""
    rec = generate(rate=200, duration=60, seed=11, motion=motion, bias=0.0, gyr_noise=0.0, acc_noise=0.0)
    q = integrate_gyr(rec.gyr, rec.stamps_ns, rec.quat_ref[0])
    err = np.rad2deg(quat.total_error(rec.quat_ref, q))
    assert err.max() < 0.1
    # and it really rotates: not a trivial trajectory
    assert np.rad2deg(quat.total_error(rec.quat_ref, rec.quat_ref[:1])).max() > (10 if motion == "translation" else 45)


def test_noisy_gyro_minus_bias_integrates_to_truth() -> None:
    rec = generate(rate=200, duration=60, seed=3, bias=0.02, gyr_noise=0.004)
    bias = np.array([float(x) for x in rec.meta["gyr_bias_rad_s"].split()])
    assert np.isclose(np.linalg.norm(bias), 0.02)
    err = np.rad2deg(quat.total_error(rec.quat_ref, integrate_gyr(rec.gyr - bias, rec.stamps_ns, rec.quat_ref[0])))
    assert err.max() < 1.0  # random walk ≈ σ·√(dt·T) ≈ 0.1°; 1° leaves room
    err_biased = np.rad2deg(quat.total_error(rec.quat_ref, integrate_gyr(rec.gyr, rec.stamps_ns, rec.quat_ref[0])))
    assert err_biased.max() > 20  # uncorrected 0.02 rad/s over 60 s drifts ≈ 69°


def test_specific_force_consistent_with_orientation() -> None:
    """acc = Rᵀ(a + g): at rest it is exactly g; the world acceleration integrates to zero velocity at rest."""
    rec = generate(rate=400, duration=60, seed=5, motion="combined", gyr_noise=0.0, acc_noise=0.0, bias=0.0)
    f_world = quat.rotate(rec.quat_ref, rec.acc)
    a_world = f_world - [0.0, 0.0, GRAVITY]
    rest = ~rec.score_mask
    assert rest.sum() > 0.1 * len(rec) and rec.score_mask.sum() > 0.5 * len(rec)
    assert np.abs(a_world[rest]).max() < 1e-9
    assert np.abs(rec.gyr[rest]).max() < 1e-12
    assert np.abs(a_world).max() > 1.0  # there is translation
    dt = 1.0 / 400
    v = np.cumsum(0.5 * (a_world[1:] + a_world[:-1]) * dt, axis=0)
    assert np.abs(v[rest[1:]]).max() < 1e-3  # velocity returns to zero after each movement phase
    rot = generate(rate=200, duration=30, seed=5, motion="rotation", gyr_noise=0.0, acc_noise=0.0)
    assert np.allclose(np.linalg.norm(rot.acc, axis=1), GRAVITY)


def test_reproducible_and_options() -> None:
    a = generate(rate=100, duration=30, seed=9)
    b = generate(rate=100, duration=30, seed=9)
    c = generate(rate=100, duration=30, seed=10)
    assert np.array_equal(a.acc, b.acc) and np.array_equal(a.quat_ref, b.quat_ref)
    assert not np.array_equal(a.acc, c.acc)
    r = generate(rate=333.3, duration=10, seed=1, start_s=5.0)
    assert len(r) == 3334 and r.stamps_ns[0] == 5_000_000_000 and abs(r.rate_hz - 333.3) < 0.01
    assert np.allclose(np.linalg.norm(r.quat_ref, axis=1), 1.0)
    b3 = generate(rate=50, duration=5, seed=1, bias=(0.1, 0.0, 0.0), gyr_noise=0.0)
    assert np.allclose(b3.gyr[~b3.score_mask], [0.1, 0.0, 0.0])
    with pytest.raises(ValueError, match="motion"):
        generate(motion="teleport")
    with pytest.raises(ValueError, match="rate"):
        generate(rate=0)
    # noise levels are what was asked
    n = generate(rate=200, duration=60, seed=2, bias=0.0, gyr_noise=0.01, acc_noise=0.05)
    clean = generate(rate=200, duration=60, seed=2, bias=0.0, gyr_noise=0.0, acc_noise=0.0)
    assert abs(np.std(n.gyr - clean.gyr) - 0.01) < 0.001
