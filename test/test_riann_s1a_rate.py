"""riann_ros/estimators/riann/s1a_rate.py: the grid step for an input step, and the running median with hysteresis."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers_riann import RateTracker

from riann_ros.estimators.riann.s1a_rate import choose_step


@pytest.mark.parametrize(
    ("d", "step"),
    [
        (0.0035, 0.0035),  # inside 2-5 ms: the samples go straight in
        (0.002, 0.002),
        (0.005, 0.005),
        (0.010, 0.005),  # 100 Hz: 2 rows per sample
        (0.012, 0.004),  # 3 rows
        (0.020000000000000004, 0.005),  # a 20 ms step from ns stamps: 4 rows, not 5
        (0.040, 0.005),  # 25 Hz: 8 rows
        (0.001, 0.005),  # 1 kHz: blocks of 5 samples
        (0.0015, 0.0045),  # blocks of 3
        (0.0019, 0.0057),  # blocks of 3
        (0.00099996, 0.0049998),  # a 1 kHz clock a little fast: still blocks of 5
        (0.0050044, 0.0050044),  # a 200 Hz clock a little slow: still straight in, not up-sampled x2
        (0.0055, 0.0055),  # 10 % slack
        (0.0056, 0.0028),
        (0.0100004, 0.0050002),  # 100 Hz a little slow: 2 rows, not 3
        (0.0400043, 0.0400043 / 8),  # 25 Hz a little slow: 8 rows, not 9
    ],
)
def test_grid_step_keeps_samples_on_the_grid_inside_2_to_5_ms(d, step):
    assert choose_step(d) == pytest.approx(step, rel=1e-9)


def test_grid_step_rejects_a_non_positive_step():
    with pytest.raises(ValueError):
        choose_step(0.0)


def test_rate_tracker_switches_only_after_half_a_window_of_the_new_rate():
    r = RateTracker(0.010)  # a window of 64 steps
    for _ in range(100):
        assert not r.push(0.010)
    assert r.step == pytest.approx(0.005)
    switched_at = None
    for k in range(200):
        if r.push(0.004):  # 250 Hz from now on
            switched_at = k
            break
    # while the 64 steps mix both rates they look jittery, and the grid holds (irregular sample times sit on no
    # grid: any step in the trained range serves them); once all 64 are new, 32 more are needed to switch
    assert switched_at is not None and 80 <= switched_at <= 100, switched_at
    assert r.step == pytest.approx(0.004)
    assert r.switches == 1


@pytest.mark.parametrize(("lo", "hi"), [(0.005, 0.015), (0.002, 0.008), (0.008, 0.032)])
def test_rate_tracker_holds_the_grid_for_jittery_sample_times(lo, hi):
    """Uniformly jittered steps around 10, 5 and 20 ms: the running median wanders across the 11 ms (2 or 3
    rows per sample), 5.5 ms (straight in or 2 rows) and 22 ms (4 or 5 rows) boundaries; a grid that followed
    it would change the network's dt dozens of times (42 switches in 150 s at 5-15 ms, 0.49 -> 1.65 deg on
    BROAD 02)."""
    r = RateTracker(0.010)
    rng = np.random.default_rng(0)
    for _ in range(20000):
        r.push(float(rng.uniform(lo, hi)))
    assert r.jittery
    assert r.switches == 0
    assert 0.002 <= r.step <= 0.0055


def test_rate_tracker_ignores_dropouts_small_drift_and_does_not_flap():
    r = RateTracker(0.010)
    rng = np.random.default_rng(0)
    for k in range(2000):
        d = 0.010 * (1.0 + 0.05 * math.sin(k / 50.0)) + rng.normal(0, 2e-5)  # ±5 % drift
        if k % 100 == 50:
            d = 0.3  # a lost burst of messages
        r.push(d)
    assert r.switches == 0
    assert r.step == pytest.approx(0.005)
    assert not r.irregular
