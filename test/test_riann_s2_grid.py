"""riann_ros/estimators/riann/s2_grid.py: causal resampling onto the grid (the signal history), the rows per sample,
the carries and steps."""

from __future__ import annotations

import numpy as np
import pytest
from helpers_riann import G, RateTracker, lead_ms, ramp_stream, straight_lead_ms, swinging_stream

from riann_ros.estimators.riann import RiannEstimator
from riann_ros.estimators.riann.s1_timeline import Timeline
from riann_ros.estimators.riann.s2_grid import Grid, SignalHistory
from riann_ros.estimators.riann.stage import Samples, TimelineBlock


def _history(means: bool = False) -> SignalHistory:
    h = SignalHistory()
    for t, v in [(0.0, 0.0), (10.0, 10.0), (30.0, 50.0)]:
        h.append(t, (v, 0.0, 0.0, 2 * v, 0.0, 0.0))
    return h


def test_curved_point_samples_integrate_a_parabola_exactly_and_only_between_even_steps():
    """Up-sampled point samples are read as the parabola through the newest three: the mean of x = t²
    over a cell is exact (the line through two samples overestimates it); uneven steps (a hole, a rate
    change) fall back to the line, and so does the first interval (no third sample yet)."""
    h = SignalHistory()
    for t in (0.0, 10.0, 20.0, 30.0):
        h.append(t, (t * t, 0.0, 0.0, -t * t, 0.0, 0.0))
    exact = (28.0**3 - 22.0**3) / 3.0 / 6.0  # mean of t² over (22, 28]
    curved = h.mean(22.0, 28.0, means=False, curved=True)
    assert curved[0] == pytest.approx(exact, rel=1e-12) and curved[3] == pytest.approx(-exact, rel=1e-12)
    line = h.mean(22.0, 28.0, means=False)
    assert line[0] == pytest.approx(400.0 + 0.5 * 500.0, rel=1e-12) and line[0] > exact + 5.0
    exact2 = (25.0**3 - 15.0**3) / 3.0 / 10.0  # a window over two intervals, both curved
    assert h.mean(15.0, 25.0, means=False, curved=True)[0] == pytest.approx(exact2, rel=1e-12)
    assert h.mean(2.0, 8.0, means=False, curved=True)[0] == h.mean(2.0, 8.0, means=False)[0]  # first interval
    uneven = SignalHistory()
    for t in (0.0, 5.0, 20.0):  # steps 5 and 15: more than 2x apart
        uneven.append(t, (t * t, 0.0, 0.0, 0.0, 0.0, 0.0))
    assert uneven.mean(8.0, 12.0, means=False, curved=True) == uneven.mean(8.0, 12.0, means=False)
    double = SignalHistory()  # steps exactly 2x apart (jitter:10/20/30ms): the line, whatever the rounding
    for t in (0.0, 10.0, 30.0):
        double.append(t, (t * t, 0.0, 0.0, 0.0, 0.0, 0.0))
    assert double.mean(12.0, 18.0, means=False, curved=True) == double.mean(12.0, 18.0, means=False)
    h.trim(15.0)
    assert list(h.t) == [0.0, 10.0, 20.0, 30.0]  # the interval around 15, (10, 20], needs the sample at 0
    h.trim(25.0)
    assert list(h.t) == [10.0, 20.0, 30.0]
    assert h.mean(22.0, 28.0, means=False, curved=True)[0] == pytest.approx(exact, rel=1e-12)


def test_an_empty_window_gives_the_value_not_a_division_by_zero():
    """A grid cell whose width rounds away next to a ns stamp (a clock period equal to the grid step up to
    1e-17 s: a FIFO read 4 at a time crashed the estimator this way) is read as the value at its end."""
    h = _history()
    assert h.mean(1e18, 1e18, means=False) == h.value(1e18, means=False)
    assert h.mean(20.0, 20.0, means=False, lo=3, hi=6) == pytest.approx([60.0, 0.0, 0.0])
    r = RateTracker(0.0035)
    r.step = 0.0035 * (1.0 + 1e-15)  # the step chosen for a clock period that has since moved by rounding
    assert r.box_width() == 0.0


def test_signal_history_interpolates_point_samples_and_holds_interval_means():
    h = _history()
    assert h.value(5.0, means=False)[0] == pytest.approx(5.0)
    assert h.value(20.0, means=False)[3] == pytest.approx(60.0)
    assert h.value(-5.0, means=False)[0] == 0.0  # before the first sample: held
    assert h.value(40.0, means=False)[0] == 50.0  # after the last: held
    # interval means: sample k holds over (t_{k-1}, t_k]
    assert h.value(5.0, means=True)[0] == 10.0
    assert h.value(10.0, means=True)[0] == 10.0
    assert h.value(10.5, means=True)[0] == 50.0


def test_signal_history_mean_is_the_exact_integral_of_the_signal_model():
    h = _history()
    # linear: over (0, 30] the integral is 10*5 + 20*30 = 650
    assert h.mean(0.0, 30.0, means=False)[0] == pytest.approx(650.0 / 30.0)
    assert h.mean(5.0, 20.0, means=False, lo=3, hi=4)[0] == pytest.approx(2 * (5 * 7.5 + 10 * 20.0) / 15.0)
    # interval means: (5, 20] = 5 s of 10 and 10 s of 50
    assert h.mean(5.0, 20.0, means=True)[0] == pytest.approx((5 * 10.0 + 10 * 50.0) / 15.0)
    # beyond the last sample the last value is held
    assert h.mean(25.0, 35.0, means=False)[0] == pytest.approx((5 * 45.0 + 5 * 50.0) / 10.0)


def test_slow_input_runs_the_network_on_a_5_ms_grid_and_fast_input_in_blocks():
    est = RiannEstimator()
    n = 250
    acc = np.tile([0.0, 0.0, G], (n, 1))
    est.update_batch(acc, np.zeros((n, 3)), np.full(n, 0.040))  # 25 Hz
    assert est.network.rows == pytest.approx(8 * n, abs=10)  # rows up to a quarter step (2 rows) before the stamp
    est.reset()
    est.update_batch(np.tile(acc, (20, 1)), np.zeros((20 * n, 3)), np.full(20 * n, 0.001))  # 1 kHz
    assert est.network.rows == pytest.approx(20 * n / 5, abs=5)


def test_a_clean_stream_at_the_grid_step_is_fed_straight_in():
    """2-5 ms streams: grid rows are the samples themselves, vectorised or sample by sample."""
    rng = np.random.default_rng(3)
    n = 400
    acc = np.array([0.0, 0.0, G]) + rng.normal(0, 0.3, (n, 3))
    gyr = rng.normal(0, 0.5, (n, 3))
    est = RiannEstimator(gyro_bias_estimation=False)
    qb = est.update_batch(acc, gyr, np.full(n, 0.004))
    assert est.network.rows == n
    est.reset()
    qs = np.array([est.update(acc[i], gyr[i], 0.004) for i in range(n)])
    assert np.abs(qb - qs).max() < 1e-5


@pytest.mark.slow
@pytest.mark.parametrize("rate", [25.0, 50.0, 100.0])
def test_up_sampling_adds_no_lag(rate):
    """Point samples read at their stamps and up-sampled onto the 5 ms grid are timed as the same signal fed
    straight in at 200 Hz: a row is the signal's mean over the cell *centred* on its grid point. (A cell ending at
    the grid point put every row half a cell, 2.5 ms, late.)"""
    assert lead_ms("points", data_means=False, rate=rate) == pytest.approx(straight_lead_ms(), abs=0.5)


@pytest.mark.parametrize("jitter", [True, False])
def test_grid_block_equals_samples(jitter):
    """Jittery stamps (no sample delay once judged jittery, after 16 steps) and a regular 100 Hz stream (up-sampled,
    read a quarter step early)."""
    x, dt = swinging_stream(2000, jitter=jitter)
    tl = Timeline(0.1, "auto").run(Samples.of(x, dt))
    assert {s.delay_s for s in tl.spec} == ({0.0} if jitter else {0.0, 0.0025})
    whole = Grid().run(tl)
    grid = Grid()
    rows, steps, forks, r0, r1 = [], [], [], [], []
    for k in range(len(x)):
        sub = TimelineBlock(Samples.of(x[k:k + 1], dt[k:k + 1]), tl.t_ns[k:k + 1], tl.spec[k:k + 1],
                            tl.start[k:k + 1], tl.switched[k:k + 1], [h._replace(sample=0) for h in tl.holes
                                                                      if h.sample == k])
        g = grid.run(sub)
        forks += [len(rows) + p for p in g.forks]
        r0.append(len(rows) + g.r0[0])
        r1.append(len(rows) + g.r1[0])
        rows += g.rows
        steps += g.row_step_s
        assert np.allclose(g.gyr_delta_rad_s[0], whole.gyr_delta_rad_s[k], rtol=0, atol=1e-9)
        assert np.allclose(g.gyr_carry_rad_s[0], whole.gyr_carry_rad_s[k], rtol=0, atol=1e-9)
    assert rows == whole.rows and steps == whole.row_step_s and forks == whole.forks
    assert r0 == whole.r0 and r1 == whole.r1
    assert len(whole.forks) == 1 and len(rows) > 2000  # up-sampled to the grid


def test_grid_reads_a_delayed_sample_as_the_signal_that_much_before_its_stamp():
    """Regular 50 Hz point samples of a ramp read a quarter step (5 ms) early: the rows (5 ms grid) are the ramp's
    means over the cells centred on the grid points of the shifted timeline, made as soon as the signal time reaches
    a cell's end; the newest row is carried to the stamp (half a cell on the signal, then the newest sample held
    over the 5 ms); from stamp to stamp the gyro is the signal between the two signal times less the previous carry
    plus the new one (the carries and the steps add up)."""
    x, dt = ramp_stream(50.0, 200)
    g = Grid().run(Timeline(0.1, "auto", 0.25).run(Samples.of(x, dt)))  # the delay from sample 16 on (judged regular)
    tau = 0.005 * np.arange(len(g.rows))  # the first grid point on the first sample
    rows = np.array(g.rows)
    later = np.arange(len(rows)) >= g.r0[20]
    np.testing.assert_allclose(rows[later, 3], 0.5 + 0.1 * (tau[later] + 0.005), atol=1e-9)
    for k in range(20, 200):
        assert g.r1[k] - g.r0[k] == 4 and tau[g.r1[k] - 1] == pytest.approx(k / 50 - 0.010, abs=1e-9)
        assert g.carry_s[k] == pytest.approx(0.010, abs=1e-9)
        on_signal = 0.5 + 0.1 * (k / 50 - 0.0025)  # the ramp's mean over the half cell before the signal time
        assert g.gyr_carry_rad_s[k][0] == pytest.approx(0.5 * (on_signal + 0.5 + 0.1 * k / 50), abs=1e-9)
        w_prev, w = 0.5 + 0.1 * (k - 1) / 50, 0.5 + 0.1 * k / 50
        want = 0.5 * (w_prev + w) * 0.020 - w_prev * 0.005 + w * 0.005
        assert g.gyr_delta_rad_s[k][0] * g.delta_s[k] == pytest.approx(want, abs=1e-9)
