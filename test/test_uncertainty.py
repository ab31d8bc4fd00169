"""The per-sample uncertainty the estimators report (AttitudeEstimator.sigma): RIANN's model (stage 8) against the
documented constants of the classical filters, batch equal to per sample, and the σ never feeding back."""

from __future__ import annotations

import math
from pathlib import Path

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
    # the per-sample formula (plain floats) is the vectorised one the fit uses
    from riann_ros.estimators.riann.s8_uncertainty import heading_sigma

    assert np.allclose(inclination_sigma(f), s_b[:, 0], rtol=1e-12)
    assert np.allclose(heading_sigma(est.uncertainty.yaw_features, s_b[:, 0]), s_b[:, 1], rtol=1e-12)
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


def test_riann_sigma_after_a_gap_is_the_fresh_network_s_until_it_has_converged():
    """A gap (longer than the gate's max_dt) restarts the network without a bridge: the output is the fresh
    network, whose σ_f (stage 6) is reported from the first sample on and decays with its re-convergence time, then
    the converged network's σ again; per sample equals batch, in σ and in the attitude."""
    from riann_ros.estimators.riann.s6_handover import FRESH_DONE, S_REST, TAU

    n = 2500
    acc, gyr, dt = _motion(n, seed=7)
    cut = 1300  # a gap before this sample (in motion, which starts at sample 1250)
    batch = RiannEstimator()
    batch.update_batch(acc[:cut], gyr[:cut], dt[:cut])
    before = batch.sigma(np.zeros(cut, dtype=bool))[-1, 0]
    batch.on_gap()
    q_b = batch.update_batch(acc[cut:], gyr[cut:], dt[cut:])
    s_b = batch.sigma(np.zeros(n - cut, dtype=bool))[:, 0]
    one = RiannEstimator(model=batch.model)
    for i in range(cut):
        one.update(acc[i], gyr[i], dt[i])
    one.on_gap()
    q_1, s_1 = [], []
    for i in range(cut, n):
        q_1.append(one.update(acc[i], gyr[i], dt[i]))
        s_1.append(one.sigma(np.zeros(1, dtype=bool))[0, 0])
    assert np.abs(np.array(s_1) - s_b).max() < 1e-6  # the network's call-length rounding (BENCHMARKS, network)
    assert np.abs(np.array(q_1) - q_b).max() < 1e-6
    # the fresh network's σ: at least S_REST at the restart, far above the converged network's σ before the gap
    assert s_b[0] >= math.radians(S_REST) and s_b[0] > 3.0 * before
    peak = int(np.argmax(s_b))  # it grows while faster rotation is seen, then decays with TAU
    k = peak + round(2 * TAU * RATE)
    assert s_b[k] < 0.2 * s_b[peak]
    # ended once below FRESH_DONE (deg): the base model again, as it was before the gap
    assert one.handover.fresh is None and batch.handover.fresh is None
    assert max(one.handover.fresh_sd) < FRESH_DONE
    # without the gap the same samples report the converged network's σ: far below at the restart, alike at the end
    plain = RiannEstimator(model=batch.model)
    plain.update_batch(acc, gyr, dt)
    s_p = plain.sigma(np.zeros(n, dtype=bool))[cut:, 0]
    assert s_p[0] < 0.5 * s_b[0] and abs(s_b[-1] - s_p[-1]) < 0.5 * s_p[-1]


# -- the evaluator's scores -------------------------------------------------------------------------------------
def _gaussian_errors(sig_i: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Inclination errors (rad) of a calibrated isotropic 2-D Gaussian with per-axis σ ``sig_i``."""
    return np.hypot(rng.normal(0, 1, len(sig_i)), rng.normal(0, 1, len(sig_i))) * sig_i


def test_uncertainty_sums_score_a_calibrated_sigma_as_calibrated_and_a_constant_as_not_sharp():
    from riann_ros.evaluation.uncertainty import UncertaintySums

    rng = np.random.default_rng(1)
    n = 200_000
    s_i = np.radians(rng.uniform(0.2, 4.0, n))
    e = _gaussian_errors(s_i, rng)
    s_y = np.where(np.arange(n) < n // 2, np.radians(5.0), np.radians(20.0))
    e_y = np.abs(rng.normal(0, 1, n)) * s_y
    u = UncertaintySums()
    for part in np.array_split(np.arange(n), 7):  # chunk by chunk
        u.add(e[part], e_y[part], np.column_stack([s_i, s_y])[part])
    r = u.result()
    assert r["cover95_pct"] == pytest.approx(95.0, abs=0.3) and r["nees"] == pytest.approx(1.0, abs=0.02)
    assert r["yaw_cover95_mag_pct"] == pytest.approx(95.0, abs=0.3)
    assert r["yaw_cover95_held_pct"] == pytest.approx(95.0, abs=0.3) and r["n_yaw_held"] == n // 2
    # top decile of σ ≈ 3.6–4°, bottom ≈ 0.2–0.6°: mean errors in about that ratio
    assert r["err_top_decile_deg"] / r["err_bottom_decile_deg"] == pytest.approx(3.8 / 0.39, rel=0.1)
    # 2x overconfident: NEES 4, coverage far below 95 %; a constant σ has no sharpness
    v = UncertaintySums()
    v.add(e, e_y, np.column_stack([s_i / 2.0, np.full(n, np.radians(180.0))]))
    rv = v.result()
    assert rv["nees"] == pytest.approx(4.0, rel=0.05) and rv["cover95_pct"] < 60.0 and rv["n_yaw_mag"] == 0
    w = UncertaintySums()
    w.add(e, e_y, np.column_stack([np.full(n, np.radians(2.0)), s_y]))
    assert w.result()["err_top_decile_deg"] == pytest.approx(w.result()["err_bottom_decile_deg"], rel=0.05)
    nothing = UncertaintySums()
    nothing.add(e, e_y, np.full((n, 2), np.nan))
    assert set(nothing.result().values()) == {None}


def test_heading_samples_are_split_by_the_state_the_estimator_reports_else_by_sigma():
    """A third σ column is the estimator's heading state (1 corrected, 2 held, 0 unknown): where it says one the
    split follows it, whatever the σ; NaN (nothing said) falls back on the σ (≤ 5°: corrected)."""
    from riann_ros.evaluation.uncertainty import UncertaintySums

    s_y = np.radians([3.0, 12.0, 3.0, 12.0, 12.0, 3.0])
    state = np.array([2.0, 1.0, np.nan, np.nan, 0.0, 1.0])
    e_y = np.radians([1.0, 1.0, 1.0, 1.0, 1.0, 10.0])  # the last one outside its 95 % region
    sig = np.column_stack([np.full(6, np.radians(1.0)), s_y, state])
    u = UncertaintySums()
    u.add(np.full(6, np.radians(0.5)), e_y, sig)
    r = u.result()
    assert r["n_yaw_mag"] == 3 and r["n_yaw_held"] == 2  # (1, 2, 5) corrected, (0, 3) held, 4 unknown
    assert r["yaw_cover95_mag_pct"] == pytest.approx(200.0 / 3.0) and r["yaw_cover95_held_pct"] == 100.0


def test_riann_reports_its_heading_state_through_the_stream_the_others_none():
    from riann_ros.stream import EstimatorStream, GateConfig

    n = 600
    acc, gyr, _ = _motion(n, seed=2)
    mag = np.tile([0.0, 2e-5, -4e-5], (n, 1))
    mag[:100] = mag[400:] = np.nan
    stamps = (np.arange(n) * 1e9 / RATE).astype(np.int64) + 10**9
    for name in ("riann", "vqf"):
        est = create(name)
        st = EstimatorStream(est, GateConfig())
        st.process_batch(stamps, acc, gyr, mag)
        if name == "vqf":
            assert np.isnan(st.batch_state).all()
            continue
        assert np.array_equal(st.batch_state, est.heading_state())  # one run, no restart: the last call's
        assert (st.batch_state[:100] == 0.0).all() and (st.batch_state[150:400] == 1.0).all()
        assert (st.batch_state[400:] == 2.0).all()


def test_results_rows_keep_the_uncertainty_scores_and_older_rows_read():
    from riann_ros.evaluation.compare import Comparison, Saved, compare
    from riann_ros.evaluation.compare_text import format_comparison
    from riann_ros.evaluation.results import ResultRow
    from riann_ros.evaluation.scoring import Score
    from riann_ros.evaluation.uncertainty_report import format_uncertainty_table

    def row(seq: str, est: str, cover: float | None) -> ResultRow:
        extra = {} if cover is None else {"nees": 1.1, "cover95_pct": cover, "err_bottom_decile_deg": 0.3,
                                          "err_top_decile_deg": 1.2}
        return ResultRow(sequence=seq, dataset="d", source="s", scenario="as-recorded", rate="native", rate_hz=100.0,
                         resampled=False, estimator=est, estimator_name=est, mode="offline",
                         score=Score(n_samples=10, n_scored=10, n_unestimated=0, rmse_deg=1.0, max_err_deg=2.0,
                                     **extra))

    rows = [row("t1", "riann", 90.0), row("t2", "riann", 96.0), row("t1", "old", None)]
    back = [ResultRow.from_dict(r.to_dict()) for r in rows]
    assert back[0].score.cover95_pct == 90.0 and back[0].score.sharpness == pytest.approx(4.0)
    assert back[2].score.cover95_pct is None and "cover95_pct" not in rows[2].to_dict()  # an older row
    table = format_uncertainty_table(back)
    assert "riann" in table and "old" not in table and "93.0" in table and "90.0–96.0" in table
    cmp: Comparison = compare(Saved(Path("a"), "a", "", back), Saved(Path("b"), "b", "", back))
    assert "uncertainty" in format_comparison(cmp) and "4.00" in format_comparison(cmp)


def test_riann_heading_sigma_follows_the_field():
    """9D: 180° before the first field, the field's σ (with the tilt's share and the bias drift the correction leaves)
    while it corrects, growing with the gyro's drift while it is absent; the per-sample formula equals the vectorised
    one."""
    from riann_ros.estimators.riann.s8_uncertainty import FREE, HELD, MAG_SD, USED, heading_sigma

    n = 2400
    acc, gyr, dt = _motion(n, seed=9)
    mag = np.tile([0.0, 2e-5, -4e-5], (n, 1))
    mag[:100] = np.nan  # no field yet
    mag[1600:] = np.nan  # the field goes away
    est = RiannEstimator()
    est.update_batch(acc, gyr, dt, mag)
    s = est.sigma(np.isfinite(mag).all(axis=1))
    yf = est.uncertainty.yaw_features
    assert (yf[:100, 0] == FREE).all() and (yf[200:1600, 0] == USED).all() and (yf[1600:, 0] == HELD).all()
    assert np.allclose(s[:100, 1], math.radians(YAW_FREE_SD_DEG))
    assert (yf[:, 1] == 0.0).all()  # no hole, no bridge
    tilt = yf[:, 3] * s[:, 0]  # the tilt compensation's share: tan(dip) σ_i, dip 63.4° here
    assert ((yf[200:, 3] > 1.5) & (yf[200:, 3] < 2.2)).all()  # the learned reference dip, about 63°
    # while the field corrects, the heading keeps the bias drift the correction has not yet removed (the running
    # mean of the start here: it lags by about half the drift since the first field)
    assert (yf[200:1600, 2] > 0.0).all()
    assert np.allclose(np.sqrt(s[200:1600, 1] ** 2 - tilt[200:1600] ** 2 - yf[200:1600, 2] ** 2), MAG_SD)
    drift = np.sqrt(s[1600:, 1] ** 2 - tilt[1600:] ** 2 - MAG_SD**2)
    assert yf[1599, 2] < drift[0] < drift[-1] < math.radians(180.0)
    assert np.allclose(heading_sigma(yf, s[:, 0]), s[:, 1], rtol=1e-12)


@pytest.mark.slow
def test_error_vs_sigma_plot_from_the_histograms_of_the_rows(tmp_path):
    from riann_ros.evaluation.results import ResultRow
    from riann_ros.evaluation.scoring import Accumulator
    from riann_ros.evaluation.uncertainty_report import plot_error_vs_sigma

    rng = np.random.default_rng(4)
    n = 20_000
    s_i = np.radians(rng.uniform(0.2, 4.0, n))
    e = _gaussian_errors(s_i, rng)
    q_ref = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    q = np.column_stack([np.cos(e / 2), np.sin(e / 2), np.zeros(n), np.zeros(n)])  # tilted about x by e
    acc = Accumulator()
    acc.add(q_ref, np.ones(n, dtype=bool), q, np.column_stack([s_i, np.full(n, np.pi)]))
    score = acc.result()
    assert score.cover95_pct == pytest.approx(95.0, abs=0.6) and score.sigma_hist is not None
    row = ResultRow(sequence="t", dataset="d", source="s", scenario="as-recorded", rate="native", rate_hz=100.0,
                    resampled=False, estimator="riann", estimator_name="riann", mode="offline", score=score)
    back = ResultRow.from_dict(row.to_dict())
    assert back.score.sigma_hist == score.sigma_hist
    paths = plot_error_vs_sigma([back], tmp_path)
    assert {p.name for p in paths} == {"error_vs_sigma.png", "error_vs_sigma.svg"}
    assert plot_error_vs_sigma([], tmp_path) == []
