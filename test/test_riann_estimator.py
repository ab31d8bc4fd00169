"""riann_ros/estimators/riann/estimator.py: the chain as one estimator: parameters, a block equals its samples,
causality, restarts from outside, the input parsed."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers_mag import moving, sign_aligned, static
from helpers_riann import G, field_rows, fifo_stamps, receive_stamps, swinging_stream, tilted_rest

from conftest import gate_dts
from riann_ros import quaternion as quat
from riann_ros.estimators import create
from riann_ros.estimators.riann import RiannEstimator
from riann_ros.estimators.riann.s4b_model import BatchedModel
from riann_ros.estimators.riann.stage import NetworkIn, Samples
from riann_ros.magcal.frontend import LatencySettings
from riann_ros.stream import EstimatorStream, GateConfig


@pytest.fixture(scope="module")
def model():
    return BatchedModel(copies=4)


def test_unknown_parameter_and_bad_model_path_are_rejected(tmp_path):
    with pytest.raises(ValueError, match="unknown parameter"):
        create("riann", beta=0.1)
    with pytest.raises(FileNotFoundError):
        create("riann", model_path=str(tmp_path / "missing.onnx"))
    bad = tmp_path / "bad.onnx"
    bad.write_bytes(b"not a model")
    with pytest.raises(Exception):  # noqa: B017 - onnxruntime's own error type
        create("riann", model_path=str(bad))


@pytest.mark.slow
def test_streaming_equals_batch_on_broad(broad_trial):
    rec = broad_trial("02").slice(0, 4000)
    est = create("riann")
    dt = gate_dts(rec)
    qb = est.update_batch(rec.acc, rec.gyr, dt)
    est.reset()
    qs = np.array([est.update(a, g, d) for a, g, d in zip(rec.acc, rec.gyr, dt, strict=True)])
    assert np.abs(qs - qb).max() < 1e-5
    # batch continues from the state left by an earlier call
    est.reset()
    q1 = est.update_batch(rec.acc[:1500], rec.gyr[:1500], dt[:1500])
    q2 = est.update_batch(rec.acc[1500:], rec.gyr[1500:], dt[1500:])
    assert np.abs(np.vstack([q1, q2]) - qb).max() < 1e-5


def test_reset_clears_the_hidden_state(broad_trial):
    rec = broad_trial("02").slice(20000, 21000)
    est = create("riann")
    a = est.update_batch(rec.acc, rec.gyr, gate_dts(rec))
    b = est.update_batch(rec.acc, rec.gyr, gate_dts(rec))
    est.reset()
    c = est.update_batch(rec.acc, rec.gyr, gate_dts(rec))
    assert np.abs(a - c).max() < 1e-9
    assert np.abs(a - b).max() > 1e-4  # without reset the state carries over


def test_outputs_never_depend_on_later_samples():
    """Causality: the outputs for a prefix are the same whether or not more samples follow."""
    rng = np.random.default_rng(2)
    n = 500
    dt = rng.choice([0.010, 0.020, 0.030], size=n)
    acc = np.array([0.0, 0.0, G]) + rng.normal(0, 0.3, (n, 3))
    gyr = rng.normal(0, 0.5, (n, 3))
    full = RiannEstimator().update_batch(acc, gyr, dt)
    part = RiannEstimator().update_batch(acc[:300], gyr[:300], dt[:300])
    assert np.abs(full[:300] - part).max() < 1e-9


@pytest.mark.parametrize(
    ("seed", "steps"),
    [
        (4, (0.0005, 0.003, 0.010, 0.020, 0.030, 0.15)),  # jitter, with holes
        (1, (0.001, 0.0015, 0.005, 0.01, 0.04, 0.1)),  # mixed rates: blocks, up-sampling, switches
        (2, ()),  # a 200 Hz clock stamped on arrival (0-10 ms late), with two holes
        (3, "fifo"),  # a 285.7 Hz FIFO read 4 at a time (the grid step equals the clock period up to rounding)
    ],
)
@pytest.mark.slow
def test_jittery_streaming_equals_batch_and_gives_unit_quaternions(seed, steps):
    rng = np.random.default_rng(seed)
    n = 1500 if not steps else 600
    if steps == "fifo":
        dt = np.diff(fifo_stamps(n + 1, 0.0035, 4))
    elif steps:
        dt = rng.choice(steps, size=n)
    else:
        dt = np.diff(receive_stamps(n + 1, 0.005, 0.010, seed))
        dt[[700, 1100]] = (0.2, 0.35)
    acc = np.array([0.0, 0.0, G]) + rng.normal(0, 0.5, (n, 3))
    gyr = rng.normal(0, 0.3, (n, 3))
    est = RiannEstimator()
    qb = est.update_batch(acc, gyr, dt)
    est.reset()
    qs = np.array([est.update(acc[i], gyr[i], dt[i]) for i in range(n)])
    assert np.abs(qs - qb).max() < 1e-5
    assert np.allclose(np.linalg.norm(qb, axis=1), 1.0)
    assert (qb[:, 0] >= 0).all()


def test_restart_keeps_the_bias_estimate_and_heading_reset_forgets_them():
    n = 200 * 10
    acc, _ = tilted_rest(n)
    gyr = np.tile(np.radians([3.0, -2.0, 0.0]), (n, 1))
    est = RiannEstimator()
    est.update_batch(acc, gyr, np.full(n, 0.005))
    b = est.diagnostics()["gyro bias estimate (deg/s)"]
    est.on_gap()
    assert est.diagnostics()["gyro bias estimate (deg/s)"] == b
    est.reset()
    assert "gyro bias estimate (deg/s)" not in est.diagnostics()


def test_a_gap_longer_than_max_dt_keeps_the_bias_estimate_a_clock_jump_forgets_it():
    n = 200 * 10
    acc, _ = tilted_rest(n)
    gyr = np.tile(np.radians([3.0, -2.0, 0.0]), (n, 1))
    stamps = (np.arange(n) * 5_000_000).astype(np.int64)
    s = EstimatorStream(RiannEstimator(), GateConfig(nominal_rate=200.0, max_dt=0.5))
    s.process_batch(stamps, acc, gyr)
    learned = np.array(s.estimator.bias.bias)
    assert np.abs(np.degrees(learned) - [3.0, -2.0, 0.0]).max() < 0.5
    # 1 s later: a gap (messages lost, same sensor)
    q, r = s.process(int(stamps[-1]) + 1_000_000_000, acc[0], gyr[0])
    assert r.reset == "gap" and q is not None
    assert np.abs(np.array(s.estimator.bias.bias) - learned).max() < math.radians(0.05)
    # 10 s back: a clock jump (a bag loop, a new recording)
    q, r = s.process(int(stamps[-1]) - 10_000_000_000, acc[0], gyr[0])
    assert r.reset == "clock_jump" and q is not None
    assert np.abs(np.degrees(s.estimator.bias.bias)).max() < 0.5


@pytest.mark.slow
@pytest.mark.parametrize("jitter", [True, False])
def test_estimator_block_equals_samples(model, jitter):
    x, dt = swinging_stream(1500, jitter=jitter)
    mag = field_rows(len(x))
    a = np.array([r[:3] for r in x])
    g = np.array([r[3:] for r in x])
    m = np.array([v if v is not None else (np.nan,) * 3 for v in mag])
    whole = RiannEstimator(model=model).update_batch(a, g, dt, m)
    est = RiannEstimator(model=model)
    one = np.vstack([est.update(a[k], g[k], dt[k], m[k]) for k in range(len(x))])
    assert np.abs(one - whole).max() < 1e-5
    assert est.network.holes == 1


def test_after_a_hole_the_stages_act_at_the_hole(model):
    x, dt = swinging_stream(1200, jitter=False)
    est = RiannEstimator(model=model)
    tl = est.timeline.run(Samples.of(x, dt))
    assert [h.sample for h in tl.holes] == [600]
    g = est.grid.run(tl)
    assert g.forks == [g.r1[600]] and g.holes == tl.holes  # the fresh state starts after the hole sample's rows
    b = est.bias.run(g)
    est.network.run(NetworkIn(g, b))
    assert est.network.holes == 1


@pytest.mark.parametrize("kind", [list, tuple, np.array, "float32"])
def test_a_sample_is_read_from_a_list_a_tuple_or_an_array(model, kind):
    acc, gyr, mag = [9.0, 1.0, 2.0], [0.1, -0.2, 0.3], [20e-6, 0.0, -40e-6]
    want = RiannEstimator(model=model).update(acc, gyr, 0.005, mag)
    conv = (lambda v: np.array(v, dtype=np.float32).astype(np.float64)) if kind == "float32" else kind
    got = RiannEstimator(model=model).update(conv(acc), conv(gyr), 0.005, conv(mag))
    assert np.abs(got - want).max() < 1e-6


def test_runtime_parameters_reach_their_stages(model):
    est = RiannEstimator(model=model)
    est.set_params(tau_mag=3.0, mag_delay=0.02, mag_dist_rejection=False, estimate_mag_delay=False,
                   hole_blend=False)
    m = est.heading.mag
    assert (m.tau_mag, m.reject) == (3.0, False)
    assert m.front.latency_settings == LatencySettings(0.02, estimate=False, compensate=True)
    assert not est.handover.enabled
    est.reset()  # a reset keeps what was set (the parameters are the estimator's)
    assert est.heading.mag.tau_mag == 3.0 and not est.handover.enabled
    with pytest.raises(ValueError, match="cannot change at run time"):
        est.set_params(ensemble=1)


@pytest.mark.parametrize("row", [
    pytest.param([0.0, 0.0, 0.0], id="zero"),
    pytest.param([0.0, 0.0, 1e-300], id="tiny"),
    pytest.param([np.inf, 0.0, 0.0], id="inf"),
    pytest.param([-np.inf, 20e-6, -40e-6], id="minus_inf"),
])
def test_riann_unusable_field_row_is_no_field(row: list[float]) -> None:
    """Called directly (no MagInput in front), a row without heading information is a sample without a field,
    in update and update_batch alike."""
    rec = moving(duration=4.0, seed=6)
    assert rec.mag is not None
    ref_mag = rec.mag.copy()
    ref_mag[200:203] = np.nan
    mag = rec.mag.copy()
    mag[200:203] = row
    q_ref = create("riann").update_batch(rec.acc, rec.gyr, rec.dt, ref_mag)
    est = create("riann")
    q_one = np.array([est.update(rec.acc[i], rec.gyr[i], float(rec.dt[i]), mag[i]) for i in range(len(rec))])
    np.testing.assert_allclose(sign_aligned(q_ref, q_one), q_ref, rtol=0, atol=1e-5)
    q = create("riann").update_batch(rec.acc, rec.gyr, rec.dt, mag)
    assert np.isfinite(q).all()
    np.testing.assert_allclose(q, q_ref, rtol=0, atol=1e-9)


def test_riann_heading_observed_flag() -> None:
    est = create("riann")
    assert not est.heading_observed()
    rec = static(quat.IDENTITY, 50)
    assert rec.mag is not None
    est.update_batch(rec.acc[:10], rec.gyr[:10], rec.dt[:10])
    assert not est.heading_observed()  # 6D
    est.update_batch(rec.acc[10:20], rec.gyr[10:20], rec.dt[10:20], rec.mag[10:20])
    assert est.heading_observed()
    est.update(rec.acc[20], rec.gyr[20], 0.01)
    assert not est.heading_observed()
    est.update(rec.acc[21], rec.gyr[21], 0.01, rec.mag[21])
    assert est.heading_observed()
    est.reset()
    assert not est.heading_observed()


def test_riann_batch_without_field_after_a_field() -> None:
    """A batch without ``mag`` after one with a field runs 6D with the heading held."""
    rec = static(quat.IDENTITY, 200)
    assert rec.mag is not None
    est = create("riann")
    q9 = est.update_batch(rec.acc[:100], rec.gyr[:100], rec.dt[:100], rec.mag[:100])
    q = est.update_batch(rec.acc[100:], rec.gyr[100:], rec.dt[100:])
    assert not est.heading_observed()
    assert np.degrees(quat.heading_error(q9[-1:], q)).max() < 0.5
