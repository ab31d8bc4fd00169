"""riann_ros/evaluation/uncertainty.py: the uncertainty scores (NEES, coverage, sharpness), and the documented
constants the classical filters report."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from helpers_riann import still_then_turning

from riann_ros.defaults import INCLINATION_SD_DEG, MAG_HEADING_SD_DEG, YAW_FREE_SD_DEG
from riann_ros.estimators import create


@pytest.mark.parametrize("name", ["madgwick", "mahony", "vqf"])
def test_classical_filters_report_their_documented_constants(name):
    """With the field calibrated as configured (the online calibration's doubt about it: test_magcal_estimators)."""
    est = create(name, mag_calibration=False)
    acc, gyr, dt = still_then_turning(20)
    mag = np.tile([0.0, 2e-5, -4e-5], (20, 1))
    mag[:10] = np.nan
    est.update_batch(acc, gyr, dt, mag)
    s = np.degrees(est.sigma(np.isfinite(mag).all(axis=1)))
    assert np.allclose(s[:, 0], INCLINATION_SD_DEG)
    assert np.allclose(s[:10, 1], YAW_FREE_SD_DEG) and np.allclose(s[10:, 1], MAG_HEADING_SD_DEG)


def _gaussian_errors(sig_i: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Inclination errors (rad) of a calibrated isotropic 2-D Gaussian with per-axis σ ``sig_i``."""
    return np.hypot(rng.normal(0, 1, len(sig_i)), rng.normal(0, 1, len(sig_i))) * sig_i


def test_uncertainty_sums_score_a_calibrated_sigma_as_calibrated_and_a_constant_as_not_sharp():
    from riann_ros.evaluation.uncertainty import UncertaintySums

    rng = np.random.default_rng(1)
    n = 200_000
    s_i = np.radians(rng.uniform(0.2, 4.0, n))
    e = _gaussian_errors(s_i, rng)
    s_y = np.where(np.arange(n) < n // 2, np.radians(MAG_HEADING_SD_DEG), np.radians(20.0))  # a field's, a held one
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
    split follows it, whatever the σ; NaN (nothing said) falls back on the σ (at most the field's: corrected)."""
    from riann_ros.evaluation.uncertainty import UncertaintySums

    s_y = np.radians([2.0, 12.0, 2.0, 12.0, 12.0, 2.0])
    state = np.array([2.0, 1.0, np.nan, np.nan, 0.0, 1.0])
    e_y = np.radians([1.0, 1.0, 1.0, 1.0, 1.0, 10.0])  # the last one outside its 95 % region
    sig = np.column_stack([np.full(6, np.radians(1.0)), s_y, state])
    u = UncertaintySums()
    u.add(np.full(6, np.radians(0.5)), e_y, sig)
    r = u.result()
    assert r["n_yaw_mag"] == 3 and r["n_yaw_held"] == 2  # (1, 2, 5) corrected, (0, 3) held, 4 unknown
    assert r["yaw_cover95_mag_pct"] == pytest.approx(200.0 / 3.0) and r["yaw_cover95_held_pct"] == 100.0


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


def test_the_field_used_split_and_the_note_share_one_threshold():
    """A classical filter reports the field's 2.5° combined with a converging calibration's share: up to
    FIELD_USED_SD_DEG that is "field used", and report.md's note names the same figure."""
    from riann_ros.evaluation.uncertainty import FIELD_USED_SD_DEG, UncertaintySums
    from riann_ros.evaluation.uncertainty_report import NOTE

    sd = np.radians([2.5, 4.0, FIELD_USED_SD_DEG, FIELD_USED_SD_DEG + 0.5, 20.0, 180.0])
    sig = np.column_stack([np.full(6, np.radians(2.0)), sd])
    u = UncertaintySums()
    u.add(np.full(6, np.radians(0.5)), np.radians(np.full(6, 1.0)), sig)
    r = u.result()
    assert (r["n_yaw_mag"], r["n_yaw_held"]) == (3, 2)  # 2.5°, 4° and the threshold itself; 180°: not counted
    assert f"a heading σ of at most {FIELD_USED_SD_DEG:g}°" in NOTE and FIELD_USED_SD_DEG == 5.0
