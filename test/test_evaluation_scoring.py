"""Scoring (riann_ros.evaluation.scoring): the 6D heading drift, scored after aligning the estimate's heading with the
reference's at the first scored sample, beside the unaligned heading and total errors that evo_ape reports."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from riann_ros import quaternion as quat
from riann_ros.cli.evaluate import main
from riann_ros.evaluation.scoring import Accumulator, heading_offset, yaw_aligned

ROOT = Path(__file__).resolve().parents[1]


def _yaw(deg: np.ndarray) -> np.ndarray:
    return quat.from_rotvec(np.column_stack([np.zeros(len(deg)), np.zeros(len(deg)), np.radians(deg)]))


def test_heading_drift_is_the_heading_error_since_the_first_scored_sample():
    n = 2000
    rng = np.random.default_rng(1)
    ref = quat.multiply(_yaw(np.linspace(0, 300, n)), quat.from_rotvec(rng.normal(0, 0.3, (n, 3))))
    drift = np.linspace(0.0, 12.0, n)
    tilt = quat.from_rotvec(np.column_stack([np.full(n, np.radians(0.5)), np.zeros(n), np.zeros(n)]))
    # started 70° off and drifting by 12°, tilted by 0.5° about a horizontal world axis
    est = quat.multiply(_yaw(-70.0 + drift), quat.multiply(tilt, ref))
    mask = np.arange(n) >= 500
    for chunk in (n, 333):
        acc = Accumulator(with_heading=True)
        for k in range(0, n, chunk):
            acc.add(ref[k:k + chunk], mask[k:k + chunk], est[k:k + chunk])
        s = acc.result(drift=True)
        want = drift[mask] - drift[500]
        assert s.heading_drift_rmse_deg == pytest.approx(np.sqrt(np.mean(want**2)), abs=0.05)
        assert s.heading_drift_min_deg == pytest.approx(0.0, abs=1e-6)
        assert s.heading_drift_max_deg == pytest.approx(want.max(), abs=0.05)
        assert s.heading_mean_deg == pytest.approx(np.mean(np.abs(-70.0 + drift[mask])), abs=0.05)  # unaligned
        assert s.rmse_deg == pytest.approx(0.5, abs=0.01)  # the inclination is not touched by the alignment
    assert acc.result().heading_drift_rmse_deg is None  # only when asked (6D runs)
    # the alignment itself: the heading offset at a sample, removed by rotating about the vertical
    off = heading_offset(ref[:1], est[:1])[0]
    assert np.degrees(off) == pytest.approx(70.0, abs=0.01)
    assert np.degrees(quat.heading_error(ref[:1], yaw_aligned(est[:1], off)))[0] == pytest.approx(0.0, abs=1e-9)


@pytest.mark.slow
def test_6d_heading_on_the_bundled_bags_is_drift_from_an_aligned_start(tmp_path, capsys):
    bags = sorted(str(p) for p in (ROOT / "bags").glob("*.mcap"))
    out = tmp_path / "out"
    assert main([*bags, "-e", "vqf", "-s", "as-recorded", "--heading", "--use-mag", "false", "--out", str(out),
                 "--no-plots", "-q"]) == 0
    text = capsys.readouterr().out
    rows = json.loads((out / "results.json").read_text())["results"]
    assert len(rows) == len(bags) == 4
    rot = next(r for r in rows if r["sequence"].startswith("synthetic_rotation"))
    assert rot["heading_rmse_deg"] > 80.0 and rot["heading_std_deg"] < 2.0  # the start heading, unaligned
    for r in rows:
        assert r["sensors"] == "6D" and r["heading_drift_min_deg"] == pytest.approx(0.0, abs=1e-6)
        assert r["heading_drift_rmse_deg"] < 12.0
        assert r["total_rmse_deg"] >= r["rmse_deg"]  # the unaligned total angle stays in results.json
    # the tables show the drift for 6D runs, not the unaligned heading or total angle
    assert "heading drift (6D: start heading aligned) error (°) per sequence" in text
    assert "\nheading error (°) per sequence" not in text and "total angle error (°)" not in text
    drift_line = next(ln for ln in text.splitlines() if ln.startswith("synthetic_rotation") and "vqf" in ln
                      and f"{rot['heading_drift_rmse_deg']:.2f}" in ln)
    assert f"{rot['heading_rmse_deg']:.2f}" not in drift_line
