"""riann_ros/estimators/riann/s1_timeline.py: holes, the sample model the grid reads with, the sample delay."""

from __future__ import annotations

import numpy as np
import pytest
from helpers_riann import G, RateTracker, lead_ms, ramp_stream, roll_rmse, straight_lead_ms, swing, swinging_stream

from riann_ros.estimators.riann import RiannEstimator
from riann_ros.estimators.riann.s1_timeline import Timeline
from riann_ros.estimators.riann.stage import Samples


def test_timeline_block_equals_samples():
    x, dt = swinging_stream(3000)
    whole = Timeline(0.1, "auto").run(Samples.of(x, dt))
    one = Timeline(0.1, "auto")
    parts = [one.run(Samples.of([xk], [d])) for xk, d in zip(x, dt, strict=True)]
    assert whole.t_ns == [p.t_ns[0] for p in parts]
    assert whole.spec == [p.spec[0] for p in parts]
    assert whole.switched == [p.switched[0] for p in parts]
    assert [h.sample for h in whole.holes] == [k for k, p in enumerate(parts) if p.holes] == [1500]


def test_rate_tracker_reads_widely_spread_steps_as_interval_means():
    r = RateTracker(0.020)
    rng = np.random.default_rng(1)
    for _ in range(200):
        r.push(float(rng.choice([0.010, 0.020, 0.030])))
    assert r.irregular
    assert r.median == pytest.approx(0.020)
    assert r.step == pytest.approx(0.005)
    for _ in range(200):
        r.push(0.020)
    assert not r.irregular


def test_rate_tracker_signal_model_can_be_set():
    means = RateTracker(0.020, means=True)
    points = RateTracker(0.020, means=False)
    rng = np.random.default_rng(1)
    for _ in range(200):
        means.push(0.020)
        points.push(float(rng.choice([0.010, 0.020, 0.030])))
    assert means.irregular and not points.irregular
    assert means.box_width() == pytest.approx(0.005)  # up-sampled: the grid cell (centred on the grid point)


def test_a_hole_is_counted_only_when_longer_than_restart_gap_and_four_input_steps():
    est = RiannEstimator()
    n = 400
    acc = np.tile([0.0, 0.0, G], (n, 1))
    dt = np.full(n, 0.040)  # 25 Hz: a 0.12 s step is 3 input steps, not a hole
    dt[200] = 0.12
    est.update_batch(acc, np.zeros((n, 3)), dt)
    assert est.network.holes == 0
    dt[300] = 0.2
    est.reset()
    est.update_batch(acc, np.zeros((n, 3)), dt)
    assert est.network.holes == 1


def _roll_rmse_deg(model: str, data_means: bool, rate: float = 50.0, **kw: float) -> float:
    return roll_rmse(RiannEstimator(input_model=model, gyro_bias_estimation=False, **kw), *swing(rate, data_means))


@pytest.mark.slow
def test_input_model_matches_what_a_sample_is():
    """A regular 50 Hz stream: read as what its samples are, it is timed as samples fed straight in; interval means
    stamped at the end of their interval lag by half a step (10 ms) when read as points, and point samples lead by
    as much when read as means; 'auto' without a sample delay reads points. (On this ideal swing the network's own
    lead, :func:`~helpers_riann.straight_lead_ms`, is what an RMSE would show first: timing is the test.)"""
    points_on_points = _roll_rmse_deg("points", data_means=False)
    assert _roll_rmse_deg("auto", data_means=False, sample_delay=0.0) == pytest.approx(points_on_points, abs=1e-9)
    assert lead_ms("points", data_means=False, rate=50.0) == pytest.approx(straight_lead_ms(), abs=0.5)
    assert lead_ms("means", data_means=True, rate=50.0) == pytest.approx(straight_lead_ms(), abs=0.5)
    assert lead_ms("means", data_means=False, rate=50.0) - straight_lead_ms() == pytest.approx(10.0, abs=1.0)
    assert lead_ms("points", data_means=True, rate=50.0) - straight_lead_ms() == pytest.approx(-10.0, abs=1.0)
    est = RiannEstimator(input_model="means")
    est.update_batch(*swing(50.0, True, seconds=1.0)[:3])
    assert est.diagnostics()["input model"] == "interval means (set)"


@pytest.mark.slow
@pytest.mark.parametrize("rate", [25.0, 50.0, 100.0])
def test_the_default_sample_delay_halves_the_worst_timing_error(rate):
    """Point samples and end-stamped interval means are half a step apart, and nothing on a regular stream tells
    which it is. Either fixed reading is half a step off on the other; the default (a quarter step early) is a
    quarter step off on both, one early and one late, around the network's own timing."""
    quarter = 250.0 / rate  # ms
    assert lead_ms("auto", data_means=False, rate=rate) - straight_lead_ms() == pytest.approx(quarter, abs=0.5)
    assert lead_ms("auto", data_means=True, rate=rate) - straight_lead_ms() == pytest.approx(-quarter, abs=0.5)


@pytest.mark.slow
@pytest.mark.parametrize("rate", [285.7, 100.0])
def test_a_clocked_stream_keeps_one_sample_delay(rate):
    """Stamps on arrival (a regular clock plus 0–10 ms delivery delays): fed straight in (285.7 Hz) the stream is
    read at its de-jittered stamps throughout, no delay; up-sampled (100 Hz) a quarter step early throughout. The
    grid step of such a stream is the running median of its jittered steps, a hair above or below the clock period:
    the delay must not switch with it."""
    rng = np.random.default_rng(3)
    n = 6000
    t = np.arange(n) / rate + rng.uniform(0.0, 0.010, n)
    t = np.maximum.accumulate(t + np.arange(n) * 1e-9)  # stamps never go back
    dt = np.diff(t, prepend=t[0] - 1.0 / rate)
    est = RiannEstimator()
    acc = np.array([0.0, 0.0, G])
    delays = []
    for k in range(n):
        est.update(acc, np.zeros(3), float(dt[k]))
        delays.append(est.timeline.delay())
    settled = np.array(delays[2000:])  # the clock is found within the first 1024 steps
    assert est.timeline.clock.clocked
    want = 0.0 if rate > 200 else 0.25 / rate
    assert np.allclose(settled, want, rtol=0.01, atol=1e-9), (settled.min(), settled.max())


@pytest.mark.parametrize(("rate", "model", "delay", "want"), [
    (50.0, "auto", 0.25, 0.005),  # up-sampled ×4: a quarter of 20 ms
    (25.0, "auto", 0.5, 0.020),
    (200.0, "auto", 0.25, 0.0),  # fed straight in: no delay
    (50.0, "points", 0.25, 0.0),  # a set model: as set
    (50.0, "means", 0.25, 0.0),
    (50.0, "auto", 0.0, 0.0),
])
def test_timeline_says_the_sample_delay_of_an_up_sampled_regular_stream_only(rate, model, delay, want):
    x, dt = ramp_stream(rate)
    tl = Timeline(0.1, model, delay).run(Samples.of(x, dt))
    delays = np.array([s.delay_s for s in tl.spec])
    assert not delays[:16].any()  # none before the stream is judged regular (16 steps)
    np.testing.assert_allclose(delays[16:], want, rtol=0, atol=1e-12)


def test_timeline_gives_jittery_sample_times_no_delay_and_a_clock_its_delay():
    """Random sample times: none (the sample-model test says what they are); a 50 Hz clock stamped on arrival
    (0-10 ms late): a quarter of its period once the clock test has recognised it."""
    x, dt = swinging_stream(3000)
    assert Timeline(0.1, "auto").run(Samples.of(x, dt)).spec[-1].delay_s == 0.0
    rng = np.random.default_rng(1)
    n = 1500
    stamps = np.arange(n) * 0.020 + rng.uniform(0.0, 0.010, n)
    xs, _ = ramp_stream(50.0, n)
    tl = Timeline(0.1, "auto").run(Samples.of(xs, np.diff(stamps, prepend=-0.02).tolist()))
    assert tl.spec[100].delay_s == 0.0  # jittery until the clock test has seen 256 steps
    assert tl.spec[-1].delay_s == pytest.approx(0.005, rel=1e-3)
