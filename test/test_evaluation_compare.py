"""``riann-bag-eval --compare`` (riann_ros.evaluation.compare): two runs' results.json files, their rows paired by
sequence, scenario and estimator or picked with --select-a/--select-b, the table, compare.csv and the plot; the
rows round trip through results.json (ResultRow)."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from riann_ros.cli.evaluate import main


@pytest.fixture(scope="module")
def two_runs(three, tmp_path_factory) -> tuple[Path, Path]:
    d = tmp_path_factory.mktemp("runs")
    args = [*map(str, three), "-e", "madgwick,vqf", "-s", "partially-restrictive,as-recorded", "--no-plots", "-q"]
    assert main([*args, "--out", str(d / "a")]) == 0
    assert main([*args, "--seed", "5", "--out", str(d / "b")]) == 0  # another draw of the added bias
    return d / "a", d / "b"


def test_result_rows_round_trip_through_results_json(two_runs):
    from riann_ros.evaluation.results import ResultRow

    for d in json.loads((two_runs[0] / "results.json").read_text())["results"]:
        again = ResultRow.from_dict(d).to_dict()
        assert {k: v for k, v in again.items() if k != "cpu_seconds"} == {
            k: v for k, v in d.items() if k != "cpu_seconds"}


def test_compare_prints_and_plots_the_difference(two_runs, tmp_path, capsys):
    a, b = two_runs
    out = tmp_path / "cmp"
    assert main(["--compare", str(a / "results.json"), str(b), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "A = a:" in text and "B = b:" in text and "mean B-A" in text and "per sequence" in text
    ra = {(r["sequence"], r["scenario"], r["estimator"]): r["rmse_deg"]
          for r in json.loads((a / "results.json").read_text())["results"]}
    rb = {(r["sequence"], r["scenario"], r["estimator"]): r["rmse_deg"]
          for r in json.loads((b / "results.json").read_text())["results"]}
    lines = (out / "compare.csv").read_text().splitlines()
    assert lines[0].startswith("sequence,scenario,perturbation,rate,estimator,rmse_a_deg,rmse_b_deg,diff_deg,")
    assert len(lines) - 1 == len(ra) == 3 * 2 * 2
    for line in lines[1:]:
        seq, scn, _, _, est, va, vb, diff = line.split(",")[:8]
        k = (seq, scn, est)
        assert float(va) == pytest.approx(ra[k], abs=1e-6) and float(vb) == pytest.approx(rb[k], abs=1e-6)
        assert float(diff) == pytest.approx(rb[k] - ra[k], abs=1e-5)
    diffs = [float(x.split(",")[7]) for x in lines[1:] if ",as-recorded," in x]
    assert max(abs(d) for d in diffs) < 1e-9  # the seed draws only the added bias: as-recorded is the same
    mean = np.mean([rb[k] - ra[k] for k in ra if k[1:] == ("partially-restrictive", "madgwick")])
    row = next(ln for ln in text.splitlines() if ln.startswith("madgwick") and "partially-restrictive" in ln)
    assert f"{mean:+.2f}" in row.split()
    assert (out / "compare_rmse.png").is_file() and (out / "compare_rmse.svg").is_file()
    assert not (out / "results.json").exists()  # no estimators ran


def test_compare_errors(two_runs, tmp_path, capsys):
    a, b = two_runs
    assert main(["--compare", str(a), str(tmp_path / "nope.json")]) == 1
    assert "nope.json: no such file" in capsys.readouterr().err
    bad = tmp_path / "x.json"
    bad.write_text('{"something": 1}')
    assert main(["--compare", str(a), str(bad)]) == 1
    assert "not a results.json of riann-bag-eval" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["--compare", str(a), str(b), "some.mcap"])
    assert main(["--compare", str(a), str(b), "--out", str(a)]) == 2  # a holds a run: refused without --force
    assert "already holds the results" in capsys.readouterr().err


# -- --compare of any rows, matched by sequence (evo_res) ---------------------------------------------------
def _rows(run: Path) -> list[dict]:
    return json.loads((run / "results.json").read_text())["results"]


@pytest.fixture(scope="module")
def params_runs(three, tmp_path_factory) -> tuple[Path, Path, Path]:
    """Runs on the same three bags: A with madgwick's default β, B with β = 0.1, P clean and jittered."""
    d = tmp_path_factory.mktemp("params")
    common = [*map(str, three), "-s", "as-recorded,realistic", "--no-plots", "-q"]
    assert main([*common, "-e", "madgwick,vqf", "--out", str(d / "a")]) == 0
    assert main([*common, "-e", "madgwick:beta=0.1,vqf", "--out", str(d / "b")]) == 0
    assert main([*common, "-e", "madgwick", "-p", "none", "-p", "jitter:10/20/30ms", "--out", str(d / "p")]) == 0
    return d / "a", d / "b", d / "p"


@pytest.mark.slow
def test_compare_two_runs_with_different_parameters(params_runs, tmp_path, capsys):
    a, b, _ = params_runs
    assert main(["--compare", str(a), str(b)]) == 0  # no selection: the shared labels pair, the others are listed
    text = capsys.readouterr().out
    assert "only in A (no partner in B): 6 row(s)" in text and "madgwick(beta=0.1)" in text
    assert "--select-a estimator=madgwick --select-b estimator='madgwick(beta=0.1)'" in text
    out = tmp_path / "cmp"
    assert main(["--compare", str(a), str(b), "--select-a", "estimator=madgwick", "--select-b",
                 "estimator=madgwick:beta=0.1", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "A and B differ in estimator" in text
    assert "estimator A" in text and "estimator B" in text
    ra = {(r["sequence"], r["scenario"]): r for r in _rows(a) if r["estimator"] == "madgwick"}
    rb = {(r["sequence"], r["scenario"]): r for r in _rows(b) if r["estimator"] == "madgwick(beta=0.1)"}
    lines = list(csv.DictReader((out / "compare.csv").open()))
    assert len(lines) == 3 * 2 == len(ra)
    for ln in lines:
        k = (ln["sequence"], ln["scenario"])
        assert (ln["estimator"], ln["estimator_b"]) == ("madgwick", "madgwick(beta=0.1)")
        assert float(ln["rmse_a_deg"]) == pytest.approx(ra[k]["rmse_deg"], abs=1e-6)
        assert float(ln["rmse_b_deg"]) == pytest.approx(rb[k]["rmse_deg"], abs=1e-6)
        assert float(ln["median_b_deg"]) == pytest.approx(rb[k]["median_err_deg"], abs=1e-6)
        row = next(x for x in text.splitlines() if x.startswith("madgwick") and f" {ln['sequence']} " in x
                   and ln["scenario"] in x and "B-A" not in x and x.split()[-1].startswith(("+", "-")))
        assert f"{rb[k]['rmse_deg'] - ra[k]['rmse_deg']:+.2f}" == row.split()[-1]
    assert (out / "compare_rmse.svg").is_file()
    assert 'id="estimator:madgwick → madgwick(beta=0.1)"' in (out / "compare_rmse.svg").read_text()


def test_compare_perturbed_against_clean(params_runs, capsys):
    a, _, p = params_runs
    # rows of one run: the jittered condition against the clean one, per sequence, scenario and estimator
    assert main(["--compare", str(p), str(p), "--select-a", "perturbation=none", "--select-b",
                 "perturbation=jitter:10/20/30ms", "--metric", "median"]) == 0
    text = capsys.readouterr().out
    assert "A and B differ in perturbation" in text and "median" in text.splitlines()[4]
    rows = _rows(p)
    clean = {(r["sequence"], r["scenario"]): r["median_err_deg"] for r in rows if r["perturbation"] == "none"}
    jit = {(r["sequence"], r["scenario"]): r["median_err_deg"] for r in rows if r["perturbation"] != "none"}
    per_seq = [x.split() for x in text.split("\nper sequence\n")[1].split("\n\n")[0].splitlines()[2:]]
    assert len(per_seq) == len(clean) == 6
    for cells in per_seq:
        k = (cells[-4], cells[1])
        assert cells[-1] == f"{jit[k] - clean[k]:+.2f}"
    # two runs, one clean, one perturbed only: no selection needed, the perturbation axis is not shared
    assert main(["--compare", str(a), str(p), "--select-b", "perturbation=jitter:10/20/30ms"]) == 0
    assert "differ in perturbation" in capsys.readouterr().out


def test_compare_selection_errors_and_old_files(params_runs, tmp_path, capsys):
    a, b, _ = params_runs
    assert main(["--compare", str(a), str(b), "--select-a", "estimator=kalman"]) == 1
    assert "A (" in (err := capsys.readouterr().err) and "no row with estimator=kalman" in err and "vqf" in err
    assert main(["--compare", str(a), str(b), "--select-a", "colour=red"]) == 2
    assert "FIELD=VALUE" in capsys.readouterr().err
    assert main(["--compare", str(a), str(b), "--metric", "loudness"]) == 2
    assert "heading_rmse" in capsys.readouterr().err
    # a results.json written before the statistics existed: RMSE comparisons work, its missing statistics say so
    old = tmp_path / "old"
    old.mkdir()
    data = json.loads((a / "results.json").read_text())
    keep = ("rmse_deg", "max_err_deg", "heading_rmse_deg", "total_rmse_deg")
    data["results"] = [{k: v for k, v in r.items() if not (k.endswith("_deg") or k.endswith("_s")) or k in keep
                        or k in ("rmse_deg",)} for r in data["results"]]
    (old / "results.json").write_text(json.dumps(data))
    assert main(["--compare", str(old), str(a)]) == 0
    assert "+0.00" in capsys.readouterr().out
    assert main(["--compare", str(old), str(a), "--metric", "median"]) == 1
    assert "an older results.json" in capsys.readouterr().err


@pytest.mark.slow
def test_compare_an_old_results_json_with_a_new_one_holding_an_input_without_reference(three, tmp_path, capsys):
    """The columns added for inputs without a reference, the heading drift, the reference's turn and the bias
    estimates are additive: an older results.json (without them) compares with a new run whose list also holds a bag
    without a reference; that bag's unscored rows are left out of the pairing."""
    from test_evaluation import synthetic

    from riann_ros import bagio

    rec = synthetic(name="noref", t0_ns=1_700_000_000_000_000_000)
    rec.quat_ref = None
    noref = bagio.write_recording(tmp_path / "noref.mcap", rec)
    new, old = tmp_path / "new", tmp_path / "old"
    assert main([str(three[0]), str(noref), "-e", "vqf", "-s", "as-recorded", "--heading", "--out", str(new),
                 "--no-plots", "-q"]) == 0
    capsys.readouterr()
    data = json.loads((new / "results.json").read_text())
    added = ("has_reference", "heading_drift_", "gyro_bias_", "t_offset_ref_turn_dps")
    data["results"] = [{k: v for k, v in r.items() if not k.startswith(added)} for r in data["results"]
                       if r["has_reference"]]
    for seq in data["sequences"]:
        for k in ("has_reference", "health", "agreement"):
            seq.pop(k, None)
    old.mkdir()
    (old / "results.json").write_text(json.dumps(data))
    assert main(["--compare", str(old), str(new)]) == 0
    text = capsys.readouterr().out
    assert "+0.00" in text and "only in" not in text and "noref/" not in text
    assert main(["--compare", str(new), str(new), "--metric", "heading_drift_rmse"]) == 0
    assert "heading drift RMSE" in capsys.readouterr().out
    assert main(["--compare", str(old), str(new), "--metric", "heading_drift_rmse"]) == 1
    assert "an older results.json" in capsys.readouterr().err


# -- plots: every perturbation condition, fixed colours ---------------------------------------------------




def test_9d_rows_never_pair_with_6d_rows_and_other_settings_are_named():
    from pathlib import Path

    from riann_ros.evaluation.compare import Saved, compare
    from riann_ros.evaluation.compare_text import format_comparison
    from riann_ros.evaluation.results import ResultRow
    from riann_ros.evaluation.scoring import Score

    def row(seq: str, sensors: str, rmse: float) -> ResultRow:
        return ResultRow(sequence=seq, dataset="d", source="s", scenario="as-recorded", rate="native", rate_hz=100.0,
                         resampled=False, estimator="mahony", estimator_name="mahony", mode="offline",
                         score=Score(n_samples=10, n_scored=10, n_unestimated=0, rmse_deg=rmse, max_err_deg=2 * rmse),
                         sensors=sensors)

    # A: a robust run, 9D where the trial has a magnetometer; B: the demo, 6D everywhere, another seed
    a = Saved(Path("robust_out/results.json"), "robust_out", "", [row("trial21", "9D", 23.04), row("syn", "6D", 1.0)],
              {"seed": 0, "score_from_s": 0.0})
    b = Saved(Path("demo_out/results.json"), "demo_out", "", [row("trial21", "6D", 34.37), row("syn", "6D", 1.2)],
              {"seed": 3, "score_from_s": 0.0})
    cmp = compare(a, b)
    assert [(p.sequence, p.a.sensors, p.b.sensors) for p in cmp.pairs] == [("syn", "6D", "6D")]
    assert [r.sequence for r in cmp.only_a] == ["trial21"] and [r.sequence for r in cmp.only_b] == ["trial21"]
    text = format_comparison(cmp)
    assert "NOTE: A and B were run with other settings, which every difference includes: seed: A 0, B 3" in text
    only_9d = compare(Saved(a.path, a.label, "", a.rows[:1], a.settings), Saved(b.path, b.label, "", b.rows[:1],
                                                                                 b.settings))
    assert only_9d.differing == ("sensors",)
    assert "NOTE: the sensors differ: A's rows are 9D, B's 6D" in format_comparison(only_9d)
