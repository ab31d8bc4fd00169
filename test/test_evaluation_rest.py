"""The initial rest is detected from the signals, not assumed (evaluation.rest); --rest gives it by hand."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from riann_ros import evaluation as ev
from riann_ros import quaternion as quat
from riann_ros.cli.evaluate import main
from riann_ros.evaluation import rest as rs
from riann_ros.recording import Recording

G = 9.81
BIAS = np.array([0.004, -0.006, 0.003])  # rad/s (0.23, -0.34, 0.17 °/s): a plausible turn-on bias


def recording(phases: list[tuple[float, str]], rate: float = 200.0, scored_from: float | None = None,
              bias=BIAS, noise: tuple[float, float] = (0.0, 0.0), name: str = "rec", seed: int = 0) -> Recording:
    """Exact signals of a sequence of phases ``(seconds, kind)``: ``rest``, ``yaw`` (steady 9 °/s turn about the
    vertical: constant gyro, constant acc), ``roll`` (steady 9 °/s roll), ``tilt`` (roll swinging ±20° at 1 Hz) and
    ``move`` (roll oscillation and a turn, as in test_evaluation.synthetic); roll continues from phase to phase.
    Scored from ``scored_from`` seconds (default: the last phase)."""
    yaw_rate = np.zeros(0)
    roll = np.zeros(0)
    droll = np.zeros(0)
    for secs, kind in phases:
        n = round(secs * rate)
        t = np.arange(n) / rate
        if kind == "rest":
            y, r, dr = np.zeros(n), np.zeros(n), np.zeros(n)
        elif kind == "roll":
            y, r, dr = np.zeros(n), np.radians(9.0) * t, np.full(n, np.radians(9.0))
        elif kind == "yaw":
            y, r, dr = np.full(n, np.radians(9.0)), np.zeros(n), np.zeros(n)
        elif kind == "tilt":
            a = np.radians(20.0)
            y, r, dr = np.zeros(n), a * np.sin(2 * np.pi * t), a * 2 * np.pi * np.cos(2 * np.pi * t)
        else:
            a = np.radians(25.0)
            y, r, dr = np.full(n, 0.4), a * np.sin(1.3 * t), a * 1.3 * np.cos(1.3 * t)
        r0 = roll[-1] + droll[-1] / rate if len(roll) else 0.0
        yaw_rate, roll, droll = np.r_[yaw_rate, y], np.r_[roll, r0 + r], np.r_[droll, dr]
    n = len(roll)
    t = np.arange(n) / rate
    yaw = np.cumsum(yaw_rate) / rate
    z = np.zeros(n)
    q_yaw = quat.from_rotvec(np.column_stack([z, z, yaw]))
    q_roll = quat.from_rotvec(np.column_stack([roll, z, z]))
    q = quat.multiply(q_yaw, q_roll)
    w = np.column_stack([droll, z, z]) + quat.rotate(quat.conjugate(q_roll), np.column_stack([z, z, yaw_rate]))
    acc = quat.rotate(quat.conjugate(q), np.array([0.0, 0.0, G]))
    rng = np.random.default_rng(seed)
    gyr = w + np.asarray(bias) + rng.normal(0.0, noise[0], (n, 3))
    acc = acc + rng.normal(0.0, noise[1], (n, 3))
    start = scored_from if scored_from is not None else sum(s for s, _ in phases[:-1])
    stamps = 1_700_000_000_000_000_000 + np.round(t * 1e9).astype(np.int64)
    return Recording(stamps, acc, gyr, q, t >= start - 1e-9, name=name, dataset="synth")


def summary(rec: Recording, given=None, chunk: int | None = None):
    src = ev.Source(rec.name, rec)
    if chunk:  # the same recording fed in chunks
        src.chunks = lambda: (rec.slice(a, a + chunk) for a in range(0, len(rec), chunk))  # type: ignore[method-assign]
    return ev.summarise(src, given)


# -- detection ----------------------------------------------------------------------------------------
def test_a_real_rest_is_found_and_its_mean_is_the_bias():
    rec = recording([(3.0, "rest"), (2.0, "roll"), (10.0, "move")])  # the sensor moves before it is scored
    s = summary(rec)
    assert s.i0 == 1000
    assert s.rest.source == rs.DETECTED and s.rest.start == 0
    assert s.rest.stop == 600  # the rest ends where the rolling starts
    np.testing.assert_allclose(s.rest.bias, BIAS, atol=1e-12)
    # taking the whole unscored span as the rest would remove the rolling too
    assert not np.allclose(rec.gyr[:1000].mean(axis=0), BIAS, atol=1e-3)
    _, info = ev.scenario_recording(rec, ev.RESTRICTIVE)
    np.testing.assert_allclose(np.radians(info.bias_removed_dps), BIAS, atol=1e-8)
    assert (info.rest_source, info.rest_samples, info.unscored_samples) == ("detected", s.rest.stop, 1000)
    assert info.rest_start_s == 0.0 and info.rest_end_s == pytest.approx((s.rest.stop - 1) / 200.0)


def test_the_longest_rest_is_used_and_chunking_does_not_matter():
    rec = recording([(2.0, "rest"), (1.0, "tilt"), (4.0, "rest"), (1.0, "tilt"), (8.0, "move")],
                    noise=(np.radians(0.3), 0.05))
    whole = summary(rec)
    assert whole.rest.source == rs.DETECTED
    # the 4 s rest, from where the low-passed signals have settled after the swinging (~1.3 s)
    assert 600 <= whole.rest.start <= 900 and 1390 <= whole.rest.stop <= 1401
    for chunk in (97, 1000):
        s = summary(rec, chunk=chunk)
        assert (s.rest.start, s.rest.stop) == (whole.rest.start, whole.rest.stop)
        np.testing.assert_array_equal(s.rest.bias, whole.rest.bias)
    assert np.abs(whole.rest.bias - BIAS).max() < np.radians(0.05)  # noise averaged over ~700 samples


@pytest.mark.parametrize("kind", ["yaw", "roll", "tilt"])
def test_a_moving_unscored_span_is_no_rest(kind):
    rec = recording([(4.0, kind), (10.0, "move")], bias=(0.0, 0.0, 0.0))
    s = summary(rec)
    assert s.i0 == 800 and not s.rest.found and s.rest.source == rs.NO_REST
    _, info = ev.scenario_recording(rec, ev.RESTRICTIVE)
    assert info.bias_removed_dps == [0.0, 0.0, 0.0] and info.rest_samples == 0 and info.rest_source == "none"


def test_short_quiet_spells_are_no_rest():
    rec = recording([(1.0, "tilt"), (1.2, "rest"), (1.0, "tilt"), (8.0, "move")])  # 1.2 s < REST_MIN_S
    assert not summary(rec).rest.found


def test_thresholds_are_the_documented_ones():
    assert (rs.REST_GYR_DEV_DPS, rs.REST_GYR_MAX_DPS, rs.REST_ACC_DEV, rs.REST_MIN_S, rs.REST_TAU_S) == (
        2.0, 2.0, 0.5, 1.5, 0.5)
    assert "VQF" in rs.DEFINITION
    b, a = rs.lowpass_coeffs(200.0)
    assert b.sum() / a.sum() == pytest.approx(1.0)  # unit DC gain


def test_a_large_constant_gyro_is_a_turn_not_a_bias():
    # the sensor lies still but its gyro reads 3 °/s on z: more than any plausible turn-on bias → no rest
    rec = recording([(3.0, "rest"), (8.0, "move")], bias=(0.0, 0.0, np.radians(3.0)))
    assert not summary(rec).rest.found
    assert summary(rec, given=(0.0, 2.5)).rest.source == rs.GIVEN  # --rest is the way out


# -- the scenarios and the estimators -----------------------------------------------------------------
def test_moving_before_the_scored_part_removes_no_bias_and_madgwick_stays_accurate():
    rec = recording([(4.0, "roll"), (20.0, "move")], bias=(0.0, 0.0, 0.0))  # rolls steadily while unscored
    settings = ev.EvalSettings(estimators=ev.parse_estimators("madgwick"), scenarios=[ev.RESTRICTIVE, ev.REALISTIC])
    res = ev.evaluate_source("moving.mcap", settings, recording=rec)
    assert res.error is None
    assert res.warnings == ["rec: no rest found before the first scored sample: no bias removed"]
    for row in res.rows:
        assert row.rmse_deg < 1.0, (row.scenario, row.rmse_deg)
    assert res.scenarios[ev.RESTRICTIVE]["bias_removed_dps"] == [0.0, 0.0, 0.0]
    # the whole unscored span taken as the rest: 9 °/s "bias" removed from the whole sequence
    wrong = ev.Rest(source="assumed", start=0, stop=800, gyr_mean=rec.gyr[:800].mean(axis=0))
    assert np.degrees(wrong.bias[0]) == pytest.approx(9.0)
    s = ev.summarise(ev.Source("x", rec))
    s.rest = wrong
    plan = ev.ScenarioPlan(ev.RESTRICTIVE, s)
    r = plan.apply(rec, 0)
    run = ev.OfflineRunner().start(settings.estimators, plan.gate)
    (q,) = run.feed(r)
    assert ev.score(r, q).rmse_deg > 10.0


def test_rest_given_by_hand_overrides_detection():
    rec = recording([(3.0, "rest"), (2.0, "tilt"), (10.0, "move")])
    s = summary(rec, given=(0.5, 2.0))
    assert s.rest.source == rs.GIVEN and (s.rest.start, s.rest.stop) == (100, 400)
    np.testing.assert_allclose(s.rest.bias, BIAS, atol=1e-12)
    moving = recording([(4.0, "yaw"), (10.0, "move")], bias=(0.0, 0.0, 0.0))
    s = summary(moving, given=(0.0, 2.0))  # the user insists: 9 °/s is the bias
    assert s.rest.source == rs.GIVEN and np.degrees(s.rest.bias[2]) == pytest.approx(9.0)
    assert summary(moving, given=(1.0, 30.0), chunk=300).rest.stop == len(moving)  # may reach past the onset
    with pytest.raises(ev.EvalError, match=r"--rest 20:30 holds no samples"):
        summary(moving, given=(20.0, 30.0))
    assert ev.parse_rest("0:2.5") == (0.0, 2.5)
    for bad in ("2:1", "x:1", "1", "-1:2"):
        with pytest.raises(ValueError, match="--rest"):
            ev.parse_rest(bad)


# -- the command line ---------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def moving_bag(tmp_path_factory) -> Path:
    from riann_ros import bagio

    rec = recording([(4.0, "yaw"), (10.0, "move")], bias=(0.0, 0.0, 0.0), name="moving")
    return bagio.write_recording(tmp_path_factory.mktemp("rest") / "moving.mcap", rec)


def test_cli_warns_and_reports_no_rest(moving_bag, tmp_path, capsys):
    out = tmp_path / "out"
    assert main([str(moving_bag), "-e", "madgwick", "-s", "restrictive", "--out", str(out), "--no-plots", "-q"]) == 0
    err = capsys.readouterr().err
    assert "warning: moving: no rest found before the first scored sample: no bias removed" in err
    data = json.loads((out / "results.json").read_text())
    info = data["sequences"][0]["scenarios"]["restrictive"]
    assert info["rest_source"] == "none" and info["rest_samples"] == 0 and info["bias_removed_dps"] == [0, 0, 0]
    assert data["sequences"][0]["warnings"] == ["moving: no rest found before the first scored sample: no bias removed"]
    assert "VQF" in data["settings"]["rest_definition"]
    assert data["results"][0]["rmse_deg"] < 1.0
    assert "## Warnings" in (out / "report.md").read_text()


def test_cli_rest_option(moving_bag, tmp_path, capsys):
    out = tmp_path / "given"
    args = [str(moving_bag), "-e", "madgwick", "-s", "restrictive", "--out", str(out), "--no-plots", "-q"]
    assert main([*args, "--rest", "0:2"]) == 0
    assert "no rest found" not in capsys.readouterr().err
    data = json.loads((out / "results.json").read_text())
    info = data["sequences"][0]["scenarios"]["restrictive"]
    assert info["rest_source"] == "given" and info["rest_start_s"] == 0.0
    assert info["bias_removed_dps"][2] == pytest.approx(9.0)
    assert data["settings"]["rest"] == [0.0, 2.0]
    assert main([str(moving_bag), "--rest", "2-3"]) == 2
    assert "START:END" in capsys.readouterr().err


def test_resampled_rates_use_the_rest_found_at_the_own_rate():
    # FFT resampling rings near the motion onset and the wrap-around; a 2.5 s rest then looks too short at 50 Hz
    rec = recording([(2.5, "rest"), (15.0, "move")])
    settings = ev.EvalSettings(estimators=ev.parse_estimators("madgwick"), scenarios=[ev.RESTRICTIVE],
                               rates=[50.0])
    res = ev.evaluate_source("x.mcap", settings, recording=rec)
    assert res.error is None and res.warnings == []
    info = res.scenarios[ev.RESTRICTIVE]
    assert info["rest_source"] == "detected" and info["rest_start_s"] == 0.0 and info["rest_end_s"] > 2.0
    # the resampled gyro over that span: the bias, up to the FFT's ringing from the wrap-around at the start
    np.testing.assert_allclose(np.radians(info["bias_removed_dps"]), BIAS, atol=np.radians(0.1))
    # no rest at the own rate: none at any rate
    moving = recording([(4.0, "roll"), (10.0, "move")], bias=(0.0, 0.0, 0.0))
    res = ev.evaluate_source("y.mcap", settings, recording=moving)
    assert res.warnings == ["rec (resampled to 50 Hz): no rest found before the first scored sample: no bias removed"]
