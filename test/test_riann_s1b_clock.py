"""riann_ros/estimators/riann/s1b_clock.py: stamps on arrival told from sample times, and the de-jittered timeline."""

from __future__ import annotations

import numpy as np
import pytest
from helpers_riann import RateTracker, fifo_stamps, receive_stamps, roll_rmse, swing

from riann_ros.estimators.riann import RiannEstimator
from riann_ros.evaluation.scoring import roll_pitch_deg


def test_rate_tracker_tells_a_jittered_clock_from_random_sample_times():
    """A regular sample clock stamped after random delivery delays: the time spanned by 16 steps varies
    only by the two end delays (variance ratio ~1/16), the clock's period is the mean step. Random sample
    times (independent intervals): variance ratio ~1, interval means."""
    clock = RateTracker(0.0035)
    for d in np.diff(receive_stamps(3000, 0.0035, 0.010)):
        clock.push(float(d))
    assert clock.clocked and not clock.means
    assert clock.variance_ratio() < 0.1
    assert clock.mean_step == pytest.approx(0.0035, rel=0.01)
    assert clock.step == pytest.approx(0.0035, rel=0.01)  # not the median step (~3 ms) nor blocks
    renewal = RateTracker(0.020)
    rng = np.random.default_rng(2)
    for d in rng.choice([0.010, 0.020, 0.030], 3000):
        renewal.push(float(d))
    assert not renewal.clocked and renewal.means
    assert 0.7 < renewal.variance_ratio() < 1.3
    # a FIFO read 12 at a time: 11 steps of 10 µs, one of 12 periods (median and p10-p90 all 10 µs)
    fifo = RateTracker(0.0035)
    for d in np.diff(fifo_stamps(3000, 0.0035, 12)):
        fifo.push(float(d))
    assert fifo.clocked and fifo.variance_ratio() < 0.25
    assert fifo.mean_step == pytest.approx(0.0035, rel=0.01) and fifo.step == pytest.approx(0.0035, rel=0.01)


def test_a_regular_stream_with_a_few_lost_messages_is_never_taken_for_a_clock():
    """A 285.7 Hz stream that loses 2-13 messages about once a second: one long step in the window. The
    variance ratio counts each step only once all 16 spans over it are in, so the long step does not look
    like a clock while its spans come in (counted at once, the ratio falls to ~1/16 for the 15 samples after each
    hole, and a de-jittered timeline would swallow the hole's time)."""
    r = RateTracker(0.0035)
    rng = np.random.default_rng(0)
    ever = False
    ratios = []
    for k in range(20000):
        d = 0.0035 * (1 + int(rng.integers(2, 14))) if k % 285 == 100 else 0.0035
        r.push(d)
        ever |= r.clocked
        if k > 1024:
            ratios.append(r.variance_ratio())
    assert not ever
    assert min(ratios) > 0.5, min(ratios)


@pytest.mark.slow
def test_short_holes_are_bridged_like_the_samples_they_lost():
    """The swing losing 2-13 samples every 1500 (so that each hole is alone among the tracker's 1024 steps) gives
    what the stream filled by linear interpolation gives: the grid bridges the hole on the stamps' time, not
    on a clock's."""
    acc, gyr, dt, _ = swing(285.7, means=False, seconds=30.0)
    t = np.cumsum(dt)
    keep = np.ones(len(t), bool)
    rng = np.random.default_rng(1)
    for start in range(200, len(t) - 20, 1500):
        keep[start:start + int(rng.integers(2, 14))] = False
    x = np.column_stack([acc, gyr])
    filled = x.copy()
    for i in range(6):
        filled[~keep, i] = np.interp(t[~keep], t[keep], x[keep, i])
    est = RiannEstimator(gyro_bias_estimation=False)
    q_holes = est.update_batch(acc[keep], gyr[keep], np.diff(np.concatenate([[0.0], t[keep]])))
    est.reset()
    q_filled = est.update_batch(filled[:, :3], filled[:, 3:], dt)[keep]
    roll_h, roll_f = roll_pitch_deg(q_holes)[:, 0], roll_pitch_deg(q_filled)[:, 0]
    assert not est.timeline.clock.clocked
    assert np.abs(roll_h - roll_f)[len(t) // 4:].max() < 0.5, np.abs(roll_h - roll_f).max()


@pytest.mark.slow
@pytest.mark.parametrize("delivery", ["delays", "fifo"])
def test_lost_messages_of_a_clock_stamped_on_arrival_advance_its_timeline(delivery):
    """The 200 Hz swing stamped on arrival (0-10 ms late, or a FIFO read 6 at a time) loses 3-14 messages every
    2 s. The de-jittered timeline advances by the lost periods too, and the clock period counts them (a timeline
    that swallowed each hole's time, with a period stretched by the lost share, is 9.9° and 12.7° off here; this
    one 2.1° and 3.0°, against 1.6° and 1.1° without losses)."""
    acc, gyr, dt, truth = swing(200.0, means=False, seconds=40.0)
    n = len(dt)
    stamps = receive_stamps(n, 0.005, 0.010, seed=3) if delivery == "delays" else fifo_stamps(n, 0.005, 6)
    keep = np.ones(n, bool)
    rng = np.random.default_rng(4)
    for start in range(300, n - 20, 400):
        keep[start:start + int(rng.integers(3, 15))] = False
    dt_rx = np.diff(np.concatenate([[0.0], stamps[keep]]))
    est = RiannEstimator(gyro_bias_estimation=False)
    lossy = roll_rmse(est, acc[keep], gyr[keep], dt_rx, truth[keep])
    full = roll_rmse(RiannEstimator(gyro_bias_estimation=False), acc, gyr, np.diff(np.concatenate([[0.0], stamps])),
                      truth)
    assert est.timeline.clock.clocked
    assert est.timeline.clock.period(0.0) == pytest.approx(0.005, rel=0.01)  # 2 % of the samples are lost
    assert lossy < 3.5 * full + 0.2, (lossy, full)


@pytest.mark.slow
@pytest.mark.parametrize("delivery", ["delays", "fifo"])
def test_a_clock_stamped_on_arrival_is_integrated_on_its_own_period(delivery):
    """Samples taken every 5 ms but stamped on arrival, 0-10 ms late or read out of a FIFO 12 at a time: the
    stamp steps are not the sample intervals. Fed as they are, each gyro sample is weighted by a wrong
    interval; the de-jittered timeline gives nearly the error of the true stamps."""
    acc, gyr, dt, truth = swing(200.0, means=False)
    if delivery == "delays":
        stamps = receive_stamps(len(dt), 0.005, 0.010, seed=3)
    else:
        stamps = fifo_stamps(len(dt), 0.005, 12)
    dt_rx = np.diff(np.concatenate([[0.0], stamps]))

    clean = roll_rmse(RiannEstimator(gyro_bias_estimation=False), acc, gyr, dt, truth)
    est = RiannEstimator(gyro_bias_estimation=False)
    received = roll_rmse(est, acc, gyr, dt_rx, truth)
    as_stamped = roll_rmse(RiannEstimator(gyro_bias_estimation=False, rate_adaptation=False), acc, gyr, dt_rx, truth)
    assert received < 1.3 * clean + 0.1
    assert as_stamped > 2.0 * received
    assert est.diagnostics()["input stamps"] == "regular clock + delivery jitter"
