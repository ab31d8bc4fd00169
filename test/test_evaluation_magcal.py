"""The evaluator's parts for the magnetometer calibration: the soft-iron perturbation, ``--score-from`` and the
time each estimator's calibration converged (riann_ros.evaluation)."""

from __future__ import annotations

import numpy as np
import pytest

from riann_ros import evaluation as ev
from riann_ros import quaternion as quat
from riann_ros.evaluation import perturb as pt
from riann_ros.magcal.synthetic import FIELD_ENU_T, ground_robot

D = (1.15, 0.05, 0.0, 0.0, 0.85, 0.05, 0.05, 0.0, 1.0)


def robot_with_field():
    phases = [("rest", 2.0, 0.0)] + [("turn", 6.0, 40.0), ("turn", 6.0, -40.0)] * 4
    rec = ground_robot(phases, rate_hz=100.0, mount_rpy_deg=(20.0, -15.0, 0.0), gyr_noise=0.002, seed=1)
    rec.mag = quat.rotate(quat.conjugate(rec.quat_ref), np.broadcast_to(np.asarray(FIELD_ENU_T), (len(rec), 3)))
    rec.score_mask = np.ones(len(rec), dtype=bool)
    return rec


def test_soft_iron_perturbation_multiplies_the_reading():
    rec = robot_with_field()
    cond = pt.parse_condition("magnetic:soft:" + ",".join(f"{v:g}" for v in D) + "+magnetic:offset:10,-20,-20")
    assert cond.label.startswith("magnetic:soft:1.15,0.05,0,0,0.85")
    soft, off = cond.parts
    tr = soft.start(np.random.default_rng(0))
    out = off.start(np.random.default_rng(0))(tr(rec))
    want = rec.mag @ np.reshape(D, (3, 3)).T + np.array([10e-6, -20e-6, -20e-6])
    np.testing.assert_allclose(out.mag, want, atol=1e-18)
    assert tr.info()["soft_iron"] == list(D) and tr.info()["samples"] == len(rec)
    for bad in ("magnetic:soft:1,0,0,0,1,0,0,0", "magnetic:soft:0,0,0,0,0,0,0,0,0"):  # 8 numbers; singular
        with pytest.raises(ValueError, match="magnetic:soft"):
            pt.parse_condition(bad)


def test_score_from_scores_only_the_samples_after_it_and_converged_after_is_reported():
    rec = robot_with_field()
    runs = {}
    for start in (0.0, 30.0):
        settings = ev.EvalSettings(estimators=ev.parse_estimators("madgwick,vqf:mag_calibration=false"),
                                   scenarios=[ev.AS_RECORDED], score_from_s=start,
                                   conditions=[ev.parse_condition("magnetic:offset:15,-10,5")])
        res = ev.evaluate_source("x.mcap", settings, recording=rec)
        assert res.error is None
        runs[start] = res.rows
    t = (rec.stamps_ns - rec.stamps_ns[0]) * 1e-9
    whole, late = runs[0.0][0], runs[30.0][0]
    assert whole.score.n_scored > late.score.n_scored
    assert late.score.n_scored == pytest.approx(np.count_nonzero(t >= 30.0), abs=2)
    assert late.score.heading_rmse_deg < whole.score.heading_rmse_deg  # the calibration's convergence not scored
    row = whole.to_dict()
    assert row["sensors"] == "9D" and 1.0 < row["mag_converged_after_s"] < 50.0
    assert runs[0.0][1].to_dict()["mag_converged_after_s"] is None  # calibration off


def test_score_from_is_a_command_line_option():
    from riann_ros.cli.evaluate_parser import build_parser

    args = build_parser().parse_args(["x.mcap", "--score-from", "60"])
    assert args.score_from == 60.0


def test_an_inputs_results_do_not_depend_on_the_inputs_evaluated_before_it_in_the_process():
    """A worker (--jobs, Dask) evaluates one input after another: each run's estimators start afresh (a reset keeps
    what belongs to the robot, e.g. the calibration front end's fit of the magnetometer's latency), so an input's
    rows are those it gets alone, whichever inputs the worker ran before."""
    rec = robot_with_field()
    other = robot_with_field()
    late = 5  # samples (50 ms): the other input's magnetometer lags the gyro, which its latency fit learns
    other.mag = np.vstack([np.repeat(other.mag[:1], late, axis=0), other.mag[:-late]])
    settings = ev.EvalSettings(estimators=ev.parse_estimators("madgwick,mahony,vqf"), scenarios=[ev.AS_RECORDED],
                               conditions=[ev.parse_condition("magnetic:offset:15,-10,5")])
    alone = ev.evaluate_source("a.mcap", settings, recording=rec)
    assert ev.evaluate_source("b.mcap", settings, recording=other).error is None
    after = ev.evaluate_source("a.mcap", settings, recording=rec)
    assert alone.error is None and after.error is None and len(alone.rows) == 3
    for a, b in zip(alone.rows, after.rows, strict=True):
        ra, rb = a.to_dict(), b.to_dict()
        assert ra["sensors"] == "9D" and np.isfinite(ra["yaw_nees"])
        for k in ra.keys() - {"seconds", "cpu_seconds"}:
            if isinstance(ra[k], float):
                assert ra[k] == pytest.approx(rb[k], rel=1e-12, abs=1e-12, nan_ok=True), (ra["estimator"], k)
            else:
                assert ra[k] == rb[k], (ra["estimator"], k)
