"""``riann-bag-eval --reference-sd``: the reference's own error added to every σ where coverage and NEES are scored
(riann_ros/evaluation/uncertainty.py), and the uncertainty table per dataset (uncertainty_report.py)."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from riann_ros.cli.evaluate import main
from riann_ros.datasets.synthetic import generate
from riann_ros.evaluation.uncertainty import UncertaintySums

bagio = pytest.importorskip("riann_ros.bagio")


@pytest.fixture(scope="module")
def two_datasets(tmp_path_factory) -> list[Path]:
    """Two sensors of other grades from the project's generator, each its own dataset: a good one at 100 Hz (two
    sequences) and a noisier one (4× the gyro and accelerometer noise) at 200 Hz."""
    d = tmp_path_factory.mktemp("reference_sd")
    good = [generate(rate=100.0, duration=d_s, seed=seed, motion="rotation", name=f"good_{seed}")
            for seed, d_s in ((3, 30.0), (5, 20.0))]
    noisy = generate(rate=200.0, duration=30.0, seed=4, gyr_noise=0.016, acc_noise=0.12, name="noisy_seq")
    recs = [*(dataclasses.replace(r, dataset="grade_a") for r in good), dataclasses.replace(noisy, dataset="grade_b")]
    return [bagio.write_recording(d / f"{r.name}.mcap", r) for r in recs]


def _run(args: list[str], out: Path, capsys) -> tuple[dict, str, str]:
    """results.json, stdout and report.md of one run."""
    assert main([*args, "-s", "as-recorded", "--no-plots", "-q", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    return json.loads((out / "results.json").read_text()), text, (out / "report.md").read_text()


def test_a_reference_error_in_the_errors_is_calibrated_only_with_reference_sd():
    """Errors drawn with σ² = σ_est² + σ_ref² on both tilt axes and the heading: scored with the estimator's σ
    alone they look overconfident; with σ_ref named they score as calibrated (95 %, NEES 1)."""
    rng = np.random.default_rng(7)
    n = 200_000
    s_i = np.radians(rng.uniform(0.3, 2.0, n))
    s_y = np.full(n, np.radians(2.0))  # a field's heading σ ("field used")
    ref = np.radians(1.0)
    tot_i, tot_y = np.hypot(s_i, ref), np.hypot(s_y, ref)
    e = np.hypot(rng.normal(0, 1, n), rng.normal(0, 1, n)) * tot_i
    e_y = np.abs(rng.normal(0, 1, n)) * tot_y
    sig = np.column_stack([s_i, s_y])
    plain, with_ref = UncertaintySums(), UncertaintySums(ref)
    plain.add(e, e_y, sig)
    with_ref.add(e, e_y, sig)
    p, r = plain.result(), with_ref.result()
    assert r["cover95_pct"] == pytest.approx(95.0, abs=0.3) and r["nees"] == pytest.approx(1.0, abs=0.02)
    assert r["yaw_cover95_mag_pct"] == pytest.approx(95.0, abs=0.3) and r["yaw_nees"] == pytest.approx(1.0, abs=0.02)
    assert p["cover95_pct"] < 85.0 and p["nees"] > 1.4 and p["yaw_nees"] > 1.2
    # the split of the heading samples and the σ histogram stay on the estimator's own σ
    assert r["n_yaw_mag"] == p["n_yaw_mag"] == n and r["sigma_hist"] == p["sigma_hist"]


@pytest.mark.slow
def test_reference_sd_widens_coverage_lowers_nees_and_is_shown(two_datasets, tmp_path, capsys):
    args = [str(two_datasets[2]), "-e", "riann,vqf"]
    before, text0, md0 = _run(args, tmp_path / "zero", capsys)
    after, text1, md1 = _run([*args, "--reference-sd", "1.0"], tmp_path / "one", capsys)
    assert before["settings"]["reference_sd_deg"] == 0.0 and after["settings"]["reference_sd_deg"] == 1.0
    for a, b in zip(before["results"], after["results"], strict=True):
        assert a["estimator"] == b["estimator"] and a["rmse_deg"] == b["rmse_deg"]
        assert b["cover95_pct"] >= a["cover95_pct"] and b["nees"] < a["nees"], (a, b)
        assert b["sigma_hist"] == a["sigma_hist"]  # the estimator's own σ
    assert "reference σ 1° per axis added, --reference-sd" in text1
    assert "reference σ 0° per axis added, --reference-sd" in text0
    assert "## Uncertainty (the σ each estimator reports; reference σ 1°)" in md1
    assert "the reference's own error σ_ref = 1° (`--reference-sd`" in md1
    assert "reference σ 0°" in md0
    assert "uncertainty per dataset" not in text1  # one dataset: no table per dataset


@pytest.mark.slow
def test_a_run_of_two_datasets_prints_coverage_per_dataset(two_datasets, tmp_path, capsys):
    """Pooled over the scored samples of each dataset's sequences (grade_a: two)."""
    data, text, md = _run([*map(str, two_datasets), "-e", "riann,vqf"], tmp_path / "two", capsys)
    block = text[text.index("uncertainty per dataset"):].split("\n\n")[0].splitlines()
    assert block[1].split() == ["dataset", "sensors", "estimator", "sequences", "cover95", "%", "NEES/DOF"]
    cells = {tuple(ln.split()[:3]): ln.split()[3:] for ln in block[2:]}
    assert set(cells) == {(d, "6D", e) for d in ("grade_a", "grade_b") for e in ("riann", "vqf")}
    for key, (seqs, cover, nees) in cells.items():
        rows = [r for r in data["results"] if (r["dataset"], r["sensors"], r["estimator"]) == key]
        n = np.array([r["n_scored"] for r in rows], dtype=float)
        assert int(seqs) == len(rows) == (2 if key[0] == "grade_a" else 1)
        assert float(cover) == pytest.approx(np.dot(n, [r["cover95_pct"] for r in rows]) / n.sum(), abs=0.05)
        assert float(nees) == pytest.approx(np.dot(n, [r["nees"] for r in rows]) / n.sum(), abs=0.005)
    assert "Uncertainty per dataset" in md and "| grade_b | 6D | vqf | 1 |" in md


@pytest.mark.parametrize("value", ["-1", "nan", "inf"])
def test_a_reference_sd_that_is_no_angle_is_a_usage_error(two_datasets, value, capsys):
    assert main([str(two_datasets[0]), "--reference-sd", value, "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("riann-bag-eval: --reference-sd must be") and value in err[0]
