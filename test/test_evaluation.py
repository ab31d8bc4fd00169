"""The evaluator core (riann_ros.evaluation): scenarios, resampling, scoring, aggregation, tuning helpers."""

from __future__ import annotations

import numpy as np
import pytest

from riann_ros import evaluation as ev
from riann_ros import quaternion as quat
from riann_ros.estimators import create
from riann_ros.recording import Recording
from riann_ros.stream import EstimatorStream, GateConfig

G = 9.81


def synthetic(
    rate: float = 100.0,
    rest_s: float = 2.0,
    move_s: float = 8.0,
    gyr_bias=(0.01, -0.02, 0.005),
    name: str = "synthetic",
    t0_ns: int = 0,
) -> Recording:
    """Rest, then a tilt oscillation about x and a turn about z; exact acc (no translation) and gyro."""
    n = round((rest_s + move_s) * rate)
    t = np.arange(n) / rate
    tm = np.clip(t - rest_s, 0.0, None)
    roll = np.radians(25.0) * np.sin(1.3 * tm) * (t > rest_s)
    droll = np.radians(25.0) * 1.3 * np.cos(1.3 * tm) * (t > rest_s)
    yaw_rate = 0.4 * (t > rest_s)
    yaw = np.cumsum(yaw_rate) / rate
    q_yaw = quat.from_rotvec(np.column_stack([np.zeros(n), np.zeros(n), yaw]))
    q_roll = quat.from_rotvec(np.column_stack([roll, np.zeros(n), np.zeros(n)]))
    q = quat.multiply(q_yaw, q_roll)  # sensor → world
    # body rate: roll rate about x plus the yaw rate seen in the rolled sensor frame
    w_body = np.column_stack([droll, np.zeros(n), np.zeros(n)]) + quat.rotate(
        quat.conjugate(q_roll), np.column_stack([np.zeros(n), np.zeros(n), yaw_rate])
    )
    acc = quat.rotate(quat.conjugate(q), np.array([0.0, 0.0, G]))
    mask = t >= rest_s
    stamps = t0_ns + np.round(t * 1e9).astype(np.int64)
    return Recording(stamps, acc, w_body + np.asarray(gyr_bias), q, mask, name=name, dataset="synth")


# -- estimator specs ----------------------------------------------------------------------------------
def test_parse_estimators_labels_and_params():
    specs = ev.parse_estimators("riann, madgwick:beta=0.033,madgwick:beta=0.1, mahony:kp=1:ki=0.3")
    assert [s.label for s in specs] == ["riann", "madgwick(beta=0.033)", "madgwick(beta=0.1)", "mahony(kp=1, ki=0.3)"]
    assert specs[2].kwargs == {"beta": 0.1}
    assert specs[0].kwargs == {}


def test_parse_estimators_bool_and_errors():
    assert ev.parse_estimator("madgwick:beta=1").kwargs == {"beta": 1.0}  # integers are fine for floats
    s = ev.parse_estimator("riann:rate_adaptation=false")
    assert s.kwargs == {"rate_adaptation": False}
    with pytest.raises(ValueError, match=r"unknown estimator 'ekf'.*known: riann"):
        ev.parse_estimators("riann,ekf")
    with pytest.raises(ValueError, match=r"unknown parameter 'gain' for madgwick.*beta"):
        ev.parse_estimator("madgwick:gain=0.1")
    with pytest.raises(ValueError, match="given twice"):
        ev.parse_estimators("riann,riann")
    with pytest.raises(ValueError, match="name=value"):
        ev.parse_estimator("madgwick:0.1")
    with pytest.raises(ValueError):
        ev.parse_estimator("madgwick:beta=-1")


def test_parse_scenarios():
    assert ev.parse_scenarios("all") == list(ev.SCENARIOS)
    assert ev.parse_scenarios("paper") == [ev.RESTRICTIVE, ev.PARTIAL, ev.REALISTIC]
    assert ev.parse_scenarios("as-recorded,raw") == [ev.AS_RECORDED]
    assert ev.parse_scenarios("realistic,partial") == [ev.REALISTIC, ev.PARTIAL]
    with pytest.raises(ValueError, match="unknown scenario"):
        ev.parse_scenarios("easy")


# -- scenarios ----------------------------------------------------------------------------------------
def test_sequence_seed_is_deterministic_and_per_sequence():
    assert ev.sequence_seed(0, "a") == ev.sequence_seed(0, "a")
    assert ev.sequence_seed(0, "a") != ev.sequence_seed(0, "b")
    assert ev.sequence_seed(0, "a") != ev.sequence_seed(1, "a")
    np.testing.assert_array_equal(ev.random_bias(3, "x"), ev.random_bias(3, "x"))
    b = np.degrees(np.array([ev.random_bias(0, f"s{i}") for i in range(2000)]))
    assert abs(b.std() - ev.BIAS_STD_DPS) < 0.03 and abs(b.mean()) < 0.03


def test_scenarios_bias_and_start():
    rec = synthetic()
    true_gyr = rec.gyr - np.array([0.01, -0.02, 0.005])
    i0 = ev.summarise(ev.Source(rec.name, rec)).i0
    assert i0 == 200

    r, info = ev.scenario_recording(rec, ev.RESTRICTIVE, seed=0)
    assert len(r) == len(rec) and info.start_index == 0 and info.rest_samples == 200
    np.testing.assert_allclose(r.gyr, true_gyr, atol=1e-12)  # turn-on bias removed using the rest
    np.testing.assert_allclose(np.radians(info.bias_removed_dps), [0.01, -0.02, 0.005], atol=1e-8)
    assert info.bias_added_dps == [0.0, 0.0, 0.0]
    assert r.stamps_ns[0] > 0  # stamp 0 would be rejected by the node's gate

    p, pinfo = ev.scenario_recording(rec, ev.PARTIAL, seed=0)
    bias = ev.random_bias(0, rec.name)
    np.testing.assert_allclose(p.gyr, true_gyr + bias, atol=1e-12)
    np.testing.assert_allclose(pinfo.bias_added_dps, np.degrees(bias), atol=1e-5)

    q, qinfo = ev.scenario_recording(rec, ev.REALISTIC, seed=0)
    assert qinfo.start_index == i0 and len(q) == len(rec) - i0
    assert q.score_mask[0]
    np.testing.assert_allclose(q.gyr, true_gyr[i0:] + bias, atol=1e-12)  # same bias as partially-restrictive
    np.testing.assert_array_equal(q.quat_ref, rec.quat_ref[i0:])
    np.testing.assert_array_equal(np.diff(q.stamps_ns), np.diff(rec.stamps_ns[i0:]))

    other, _ = ev.scenario_recording(rec, ev.PARTIAL, seed=1)
    assert not np.allclose(other.gyr, p.gyr)


def test_as_recorded_is_the_recording_as_it_is():
    rec = synthetic(t0_ns=5_000_000_000)
    r, info = ev.scenario_recording(rec, ev.AS_RECORDED, seed=0)
    np.testing.assert_array_equal(r.gyr, rec.gyr)  # turn-on bias kept, nothing added
    np.testing.assert_array_equal(r.stamps_ns, rec.stamps_ns)
    assert info.bias_removed_dps == [0.0, 0.0, 0.0] and info.bias_added_dps == [0.0, 0.0, 0.0]
    assert info.start_index == 0 and info.rest_samples == 200


def test_perturbation_conditions_are_an_axis_of_the_evaluation():
    rec = synthetic(rate=200.0, move_s=20.0)
    settings = ev.EvalSettings(
        estimators=ev.parse_estimators("madgwick,vqf"),
        scenarios=[ev.AS_RECORDED],
        conditions=[ev.parse_condition("none"), ev.parse_condition("jitter:10/20/30ms+bias:3,3,0")],
    )
    res = ev.evaluate_source("x.mcap", settings, recording=rec)
    assert res.error is None
    assert [(r.perturbation, r.estimator) for r in res.rows] == [
        ("none", "madgwick"), ("none", "vqf"),
        ("jitter:10/20/30ms+bias:3,3,0", "madgwick"), ("jitter:10/20/30ms+bias:3,3,0", "vqf"),
    ]
    clean, jittered = res.rows[0], res.rows[2]
    assert jittered.score.n_samples < clean.score.n_samples / 3  # ~50 Hz from 200 Hz
    info = res.perturbations["jitter:10/20/30ms+bias:3,3,0"][ev.AS_RECORDED]
    assert info[0]["samples"] == jittered.score.n_samples and info[1]["bias_dps"] == [3.0, 3.0, 0.0]
    # the gate of the perturbed stream runs at its own nominal rate (VQF takes its sample time from it)
    agg = ev.aggregate(res.rows)
    assert {g.perturbation for g in agg} == {"none", "jitter:10/20/30ms+bias:3,3,0"}


def test_scenario_without_rest_removes_nothing():
    rec = synthetic(rest_s=0.0)
    assert ev.summarise(ev.Source(rec.name, rec)).i0 == 0
    r, info = ev.scenario_recording(rec, ev.RESTRICTIVE)
    np.testing.assert_array_equal(r.gyr, rec.gyr)
    assert info.bias_removed_dps == [0.0, 0.0, 0.0] and info.rest_samples == 0


def test_no_scored_samples_is_an_error():
    rec = synthetic()
    rec.score_mask[:] = False
    with pytest.raises(ev.EvalError, match="no scored samples"):
        ev.scenario_recording(rec, ev.REALISTIC)


# -- resampling ---------------------------------------------------------------------------------------
def test_resample_signals_reference_and_mask():
    rec = synthetic(rate=200.0, t0_ns=5_000_000_000)
    r = ev.open_source("x.mcap", 100.0, rec).rec
    assert abs(len(r) - len(rec) / 2) <= 1
    assert r.rate_hz == pytest.approx(100.0, rel=1e-6)
    assert r.stamps_ns[0] == rec.stamps_ns[0]
    # the reference is the slerp of the original at the new times: here every other original sample
    np.testing.assert_allclose(
        np.abs(np.sum(r.quat_ref[:-1] * rec.quat_ref[:-1:2][: len(r) - 1], axis=1)), 1.0, atol=1e-9
    )
    np.testing.assert_array_equal(r.score_mask[:-1], rec.score_mask[::2][: len(r) - 1])
    # FFT resampling keeps a band-limited periodic signal exactly
    t = np.arange(len(rec)) / 200.0
    period = len(rec) / 200.0
    smooth = np.column_stack([np.sin(2 * np.pi * k * t / period) for k in (3, 7, 11)])
    rec.gyr = smooth
    rec.acc = 9.81 + smooth
    r = ev.open_source("x.mcap", 50.0, rec).rec
    np.testing.assert_allclose(r.gyr, smooth[::4][: len(r)], atol=1e-9)
    np.testing.assert_allclose(r.acc, 9.81 + smooth[::4][: len(r)], atol=1e-9)


def test_resampled_stamps_are_the_times_of_the_resampled_samples():
    """1001 samples at 200 Hz to 50 Hz: 250 samples span the 1001 samples' period, so they are
    20.02 ms apart; stamps 20 ms apart would drift 5 ms from the samples by the end."""
    from riann_ros.resample import resample_recording

    rec = synthetic(rate=200.0, t0_ns=5_000_000_000).slice(0, 1001)
    period = len(rec) / 200.0
    t = np.arange(len(rec)) / 200.0
    rec.gyr = np.column_stack([np.sin(2 * np.pi * k * t / period) for k in (3, 7, 11)])
    r = resample_recording(rec, 50.0)
    tk = (r.stamps_ns - rec.stamps_ns[0]) * 1e-9
    want = np.column_stack([np.sin(2 * np.pi * k * tk / period) for k in (3, 7, 11)])
    np.testing.assert_allclose(r.gyr, want, atol=1e-6)
    assert r.rate_hz == pytest.approx(50.0, rel=2e-3)
    # the reference is taken at the same times
    ref = resample_recording(rec, 200.0)  # every sample kept: the identity
    np.testing.assert_array_equal(ref.stamps_ns, rec.stamps_ns)


# -- scoring ------------------------------------------------------------------------------------------
def test_score_inclination_ignores_heading():
    rec = synthetic()
    heading_off = quat.multiply(quat.from_rotvec([0, 0, 1.0]), rec.quat_ref)  # world-frame yaw error
    s = ev.score(rec, heading_off, with_heading=True)
    assert s.rmse_deg < 1e-5
    assert s.heading_rmse_deg == pytest.approx(np.degrees(1.0), abs=1e-6)
    assert s.total_rmse_deg == pytest.approx(np.degrees(1.0), abs=1e-6)
    tilted = quat.multiply(quat.from_rotvec([np.radians(3.0), 0, 0]), rec.quat_ref)
    assert ev.score(rec, -tilted).rmse_deg == pytest.approx(3.0, abs=1e-6)  # sign-invariant


def test_score_mask_reference_and_estimate_gaps():
    rec = synthetic()
    est = rec.quat_ref.copy()
    est[rec.score_mask.argmax()] = quat.from_rotvec([0.5, 0, 0])  # wrong, scored
    rec.quat_ref[5] = np.nan  # missing reference in the rest: not scored anyway
    est[-1] = np.nan  # rejected by the gate: not scored, counted
    s = ev.score(rec, est)
    assert s.n_scored == rec.score_mask.sum() - 1
    assert s.n_unestimated == 1
    assert s.rmse_deg > 0
    rec.quat_ref = None
    with pytest.raises(ev.EvalError, match="no reference"):
        ev.score(rec, est)


def test_offline_runner_is_the_node_stream():
    rec, _ = ev.scenario_recording(synthetic(), ev.REALISTIC)
    specs = ev.parse_estimators("riann")
    gate = GateConfig(nominal_rate=rec.rate_hz)
    run = ev.OfflineRunner().start(specs, gate)
    (q,) = run.feed(rec)
    (stats,) = run.finish()
    q2, acc2 = EstimatorStream(create("riann"), gate).process_batch(rec.stamps_ns, rec.acc, rec.gyr)
    np.testing.assert_array_equal(np.isfinite(q).all(axis=1), acc2)
    np.testing.assert_allclose(q, q2, atol=1e-6)
    assert stats.resets == {"start": 1}
    # a second run starts from scratch (reset) and gives the same numbers
    (q3,) = ev.OfflineRunner().start(specs, gate).feed(rec)
    np.testing.assert_allclose(q, q3, atol=1e-6)


@pytest.mark.slow
def test_evaluate_source_rows_and_rates():
    rec = synthetic(rate=200.0)
    settings = ev.EvalSettings(
        estimators=ev.parse_estimators("riann"),
        scenarios=list(ev.SCENARIOS),
        rates=[None, 100.0],
        series_for="*",
        keep_estimates=True,
    )
    res = ev.evaluate_source("x.mcap", settings, recording=rec)
    assert res.error is None
    assert len(res.rows) == 2 * 4
    assert {r.rate_hz for r in res.rows} == {200.0, 100.0}
    assert all(r.rmse_deg < 5.0 for r in res.rows)  # exact synthetic signals: RIANN tracks them
    assert set(res.scenarios) == set(ev.SCENARIOS)
    assert set(res.series["curves"]) == set(ev.SCENARIOS)
    est = res.estimates
    assert est["scenario"] == ev.RESTRICTIVE
    np.testing.assert_array_equal(est["stamps"], rec.stamps_ns)  # the bag's own stamps (not shifted)
    assert est["quats"]["riann"].shape == (len(rec), 4)


def row(estimator: str, dataset: str, rmse: float, scenario: str = ev.REALISTIC) -> ev.ResultRow:
    return ev.ResultRow(sequence="s", dataset=dataset, source="", scenario=scenario, rate=ev.NATIVE, rate_hz=100.0,
                        resampled=False, estimator=estimator, estimator_name=estimator, mode="offline",
                        score=ev.Score(n_samples=1, n_scored=1, n_unestimated=0, rmse_deg=rmse, max_err_deg=rmse))


def test_aggregate_mean_median_max():
    rows = [row("a", d, v) for d, v in [("x", 1.0), ("x", 2.0), ("x", 6.0), ("y", 4.0)]]
    agg = {a.dataset: a for a in ev.aggregate(rows)}
    assert agg["x"].mean == pytest.approx(3.0) and agg["x"].median == 2.0 and agg["x"].max == 6.0
    assert agg["y"].n == 1
    assert agg[ev.ALL_DATASETS].n == 4 and agg[ev.ALL_DATASETS].mean == pytest.approx(13 / 4)


# -- tuning -------------------------------------------------------------------------------------------
def test_parse_grid_and_best():
    name, grid = ev.parse_grid("madgwick:beta=0.01/0.1")
    assert name == "madgwick" and grid == {"beta": [0.01, 0.1]}
    name, grid = ev.parse_grid("mahony")
    assert set(grid) == {"kp", "ki"}
    specs = ev.grid_specs("mahony", {"kp": [1.0, 2.0], "ki": [0.0, 0.3]})
    assert len(specs) == 4 and specs[-1].kwargs == {"kp": 2.0, "ki": 0.3}
    with pytest.raises(ValueError, match="unknown parameter"):
        ev.parse_grid("madgwick:gain=1/2")
    rows = [row(s.label, "x", v) for s, v in zip(specs, [3.0, 1.0, 2.0, 4.0], strict=True)]
    best = ev.best_of(rows, specs, ev.REALISTIC)
    assert best["best"]["params"] == {"kp": 1.0, "ki": 0.3}


def test_tuning_finds_a_sensible_gain():
    # biased gyro, exact accelerometer: a Madgwick gain near zero drifts, a larger one does not
    rec = synthetic(gyr_bias=(0.0, 0.0, 0.0), move_s=20.0)
    specs = ev.grid_specs("madgwick", {"beta": [0.0, 0.1]})
    settings = ev.EvalSettings(estimators=specs, scenarios=[ev.PARTIAL], seed=4)
    res = ev.evaluate_source("synthetic", settings, recording=rec)
    best = ev.best_of(res.rows, specs, ev.PARTIAL)
    assert best["best"]["params"] == {"beta": 0.1}


def test_resample_carries_the_magnetometer():
    from riann_ros.resample import resample_recording

    rec = synthetic(rate=200.0)
    t = np.arange(len(rec)) / 200.0
    period = len(rec) / 200.0
    rec.mag = 40e-6 + 1e-6 * np.column_stack([np.sin(2 * np.pi * k * t / period) for k in (2, 5, 9)])
    r = resample_recording(rec, 100.0)
    tk = (r.stamps_ns - rec.stamps_ns[0]) * 1e-9
    want = 40e-6 + 1e-6 * np.column_stack([np.sin(2 * np.pi * k * tk / period) for k in (2, 5, 9)])
    np.testing.assert_allclose(r.mag, want, atol=1e-12)  # band-limited: FFT keeps it
    rec.mag[10:20] = np.nan  # holes: the latest sample at or before each new stamp, holes stay holes
    r = resample_recording(rec, 100.0)
    np.testing.assert_array_equal(r.mag[:30], rec.mag[0:60:2])


def test_tuning_runs_with_the_evaluations_sensors(monkeypatch):
    """--tune scores the grid as the evaluation runs (--use-mag false: 6D); in 9D Madgwick's beta is unused."""
    import importlib

    aggregate = importlib.import_module("riann_ros.evaluation.aggregate")  # the package re-exports a function so named
    seen: list[ev.EvalSettings] = []

    def capture(sources, settings, jobs=1, progress=None):
        seen.append(settings)
        return []

    monkeypatch.setattr(aggregate, "evaluate_sources", capture)
    with pytest.raises(ev.EvalError, match="no scores"):
        ev.tune("madgwick", ["x"], ev.REALISTIC, 0, like=ev.EvalSettings(estimators=[], use_mag="false"))
    assert seen[0].use_mag == "false"


def test_roll_pitch_ignore_heading():
    from riann_ros import quaternion as quat
    from riann_ros.evaluation.scoring import roll_pitch_deg

    r, p = np.radians(30.0), np.radians(-20.0)
    q_rp = quat.multiply(quat.from_rotvec([0, p, 0]), quat.from_rotvec([r, 0, 0]))
    for yaw in (0.0, 1.0, -2.5):
        q = quat.multiply(quat.from_rotvec([0, 0, yaw]), q_rp)[None]
        np.testing.assert_allclose(roll_pitch_deg(q), [[30.0, -20.0]], atol=1e-9)
