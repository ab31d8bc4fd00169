"""riann-bag-eval's files: the --out policy (an earlier run is never lost silently) and inputs to convert first."""

from __future__ import annotations

import csv
import json
import re
import shlex
from pathlib import Path

import numpy as np
import pytest
from test_evaluation import synthetic

from riann_ros.cli.convert import main as convert_main
from riann_ros.cli.evaluate import main
from riann_ros.evaluation import outdir

bagio = pytest.importorskip("riann_ros.bagio")


@pytest.fixture(scope="module")
def bag(tmp_path_factory) -> Path:
    rec = synthetic(name="seq", t0_ns=1_700_000_000_000_000_000)
    return bagio.write_recording(tmp_path_factory.mktemp("files") / "seq.mcap", rec)


def test_a_reader_that_leaves_early_costs_no_results(bag, tmp_path):
    """``riann-bag-eval … | head``: the reader closes stdout before the tables are printed; the run still writes its
    result files and exits 0, with no traceback."""
    import os
    import subprocess
    import sys

    out = tmp_path / "piped"
    root = Path(__file__).resolve().parents[1]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, "-m", "riann_ros.cli.evaluate", str(bag), "-e", "madgwick", "-s",
                             "as-recorded", "--no-plots", "--out", str(out)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, cwd=tmp_path, env=env)
    assert proc.stdout is not None and proc.stderr is not None
    proc.stdout.close()  # what `head` does once it has its lines (here: before any)
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 0, err
    assert "Traceback" not in err and "BrokenPipe" not in err
    assert (out / "results.json").is_file() and (out / "report.md").is_file()


# -- --out ----------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_out_with_an_earlier_run_is_refused_without_force(bag, tmp_path, capsys):
    out = tmp_path / "out"
    args = [str(bag), "-e", "madgwick", "-s", "realistic", "--out", str(out), "-q"]
    assert main(args) == 0
    assert (out / "error_over_time.png").is_file()
    first = (out / "results.json").read_bytes()
    capsys.readouterr()
    assert main(args) == 2  # refused before any work, nothing touched
    err = capsys.readouterr().err
    assert "already holds the results of an earlier run" in err and "--force" in err
    assert (out / "results.json").read_bytes() == first


@pytest.mark.slow
def test_force_replaces_only_the_result_files(bag, tmp_path):
    out = tmp_path / "out"
    assert main([str(bag), "-e", "madgwick", "-s", "realistic", "--out", str(out), "-q"]) == 0
    assert (out / "error_over_time.png").is_file() and (out / "error_over_time.svg").is_file()
    (out / "roll_pitch_old_sequence.png").write_bytes(b"stale")  # a per-sequence plot of the earlier run
    (out / "notes.txt").write_text("mine")  # the user's own files stay
    (out / "my_plot.png").write_bytes(b"mine")
    assert main([str(bag), "-e", "madgwick", "-s", "realistic", "--out", str(out), "--no-plots", "--force", "-q"]) == 0
    assert not (out / "error_over_time.png").exists()  # a stale plot must not survive next to new results
    assert not (out / "error_over_time.svg").exists() and not (out / "rmse_boxplots.png").exists()
    assert not (out / "roll_pitch_old_sequence.png").exists()
    assert (out / "notes.txt").read_text() == "mine" and (out / "my_plot.png").read_bytes() == b"mine"
    data = json.loads((out / "results.json").read_text())
    assert "--force" in data["settings"]["command"]


def test_an_empty_or_foreign_folder_is_fine(bag, tmp_path):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "README.txt").write_text("x")
    assert main([str(bag), "-e", "madgwick", "-s", "realistic", "--out", str(out), "--no-plots", "-q"]) == 0
    assert (out / "results.csv").is_file() and (out / "README.txt").read_text() == "x"
    assert outdir.previous_results(tmp_path / "nothing_here") == []


def test_prepare_out_api(tmp_path):
    (tmp_path / "results.csv").write_text("old")
    (tmp_path / "keep.csv").write_text("mine")
    with pytest.raises(outdir.OutputExists, match="--force"):
        outdir.prepare_out(tmp_path, replace=False)
    assert outdir.prepare_out(tmp_path, replace=True) == [tmp_path / "results.csv"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.csv"]


# -- inputs to convert first ----------------------------------------------------------------------------
def _commands(err: str) -> list[list[str]]:
    """The commands the message says to type (its indented lines)."""
    return [shlex.split(line) for line in err.splitlines() if line.startswith("    riann-bag-")]


def test_csv_input_says_how_to_convert_it(tmp_path, capsys):
    rec = synthetic(name="csvseq")
    csv = tmp_path / "imu data.csv"  # a blank in the name: the command must be quoted
    rows = np.column_stack([rec.t, rec.acc, rec.gyr, rec.quat_ref, rec.score_mask.astype(int)])
    header = "t,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z,qw,qx,qy,qz,scored"
    np.savetxt(csv, rows, delimiter=",", header=header, comments="", fmt="%.17g")
    assert main([str(csv), "-e", "madgwick", "-q"]) == 1
    err = capsys.readouterr().err
    assert "a CSV file, not a bag; convert it first with riann-bag-convert" in err
    assert "cannot read" not in err
    convert, evaluate = _commands(err)
    assert convert == ["riann-bag-convert", str(csv), "-o", str(tmp_path / "imu data.mcap")]
    assert convert_main([*convert[1:], "-q"]) == 0  # the command as printed works
    assert evaluate == ["riann-bag-eval", str(tmp_path / "imu data.mcap")]
    assert main([*evaluate[1:], "-e", "madgwick", "-s", "realistic", "-q"]) == 0


def test_euroc_folder_says_how_to_convert_it(tmp_path, capsys):
    root = tmp_path / "MH_01_easy"
    (root / "mav0" / "imu0").mkdir(parents=True)
    (root / "mav0" / "imu0" / "data.csv").write_text("#timestamp [ns],w_RS_S_x [rad s^-1]\n")
    assert main([str(root), "-q"]) == 1
    err = capsys.readouterr().err
    assert "an EuRoC/ASL folder, not a bag; convert it first with riann-bag-convert" in err
    convert, evaluate = _commands(err)
    assert convert == ["riann-bag-convert", str(root), "-o", str(tmp_path / "MH_01_easy.mcap")]
    assert evaluate == ["riann-bag-eval", str(tmp_path / "MH_01_easy.mcap")]


def test_folder_of_dataset_files_and_ros1_bags(tmp_path, capsys):
    d = tmp_path / "broad"
    d.mkdir()
    (d / "01_x.hdf5").write_bytes(b"")
    ros1 = tmp_path / "old.bag"
    ros1.write_bytes(b"#ROSBAG V2.0\n")
    assert main([str(d), str(ros1), "-q"]) == 1
    err = capsys.readouterr().err
    assert "a folder of dataset files, not a bag" in err and f"riann-bag-convert {d} -o {tmp_path}/broad_bags" in err
    assert "a ROS 1 bag" in err and f"rosbags-convert --src {ros1} --dst {tmp_path}/old" in err


# -- plots ------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def three(tmp_path_factory) -> list[Path]:
    d = tmp_path_factory.mktemp("three")
    out = []
    for i in range(3):
        rec = synthetic(name=f"s{i}", t0_ns=1_700_000_000_000_000_000, gyr_bias=(0.01 * i, -0.02, 0.005))
        rec.acc = rec.acc + np.random.default_rng(i).normal(0, 0.1, rec.acc.shape)
        out.append(bagio.write_recording(d / f"s{i}.mcap", rec))
    return out


def _capture(monkeypatch) -> list:
    from riann_ros.evaluation import plots

    figs: list = []
    monkeypatch.setattr(plots, "_save", lambda fig, out_dir, stem: figs.append((stem, fig)) or [])
    return figs


@pytest.mark.parametrize("n", [1, 3])
def test_boxplots_show_every_sequence_on_a_linear_axis(three, n, monkeypatch):
    from riann_ros import evaluation as ev
    from riann_ros.evaluation import plots

    settings = ev.EvalSettings(estimators=ev.parse_estimators("madgwick,vqf"), scenarios=["realistic", "as-recorded"])
    rows = [r for b in three[:n] for r in ev.evaluate_source(b, settings).rows]
    figs = _capture(monkeypatch)
    plots.plot_boxes(rows, Path("."))
    (_, fig), = figs
    axes = [a for a in fig.axes if a.get_title()]
    assert [a.get_title() for a in axes] == ["realistic", "as-recorded"]
    for ax in axes:
        assert ax.get_yscale() == "linear" and ax.get_ylim()[0] == 0.0
        assert ax.get_ylim()[1] >= max(r.rmse_deg for r in rows)  # nothing clipped
        points = sum(len(c.get_offsets()) for c in ax.collections)
        assert points == 2 * n  # every sequence of both estimators is a point
        assert len(ax.patches) == (2 if n >= plots.BOX_MIN_N else 0)  # boxes only from BOX_MIN_N sequences on
    legend = [t.get_text() for t in fig.legends[0].get_texts()]
    assert legend == [f"madgwick (n={n})", f"vqf (n={n})"]


def test_rmse_vs_rate_is_linear(three, monkeypatch):
    from riann_ros import evaluation as ev
    from riann_ros.evaluation import plots

    settings = ev.EvalSettings(estimators=ev.parse_estimators("madgwick"), scenarios=["realistic"], rates=[50.0, 100.0])
    rows = ev.evaluate_source(three[0], settings).rows
    figs = _capture(monkeypatch)
    plots.plot_rmse_vs_rate(rows, Path("."))
    (_, fig), = figs
    assert fig.axes[0].get_yscale() == "linear" and fig.axes[0].get_ylim()[0] == 0.0
    assert fig.legends[0].get_texts()[0].get_text() == "madgwick (n=1)"


@pytest.mark.slow
def test_roll_pitch_plot_per_sequence(three, tmp_path):
    out = tmp_path / "all"
    assert main([*map(str, three), "-e", "madgwick,vqf", "--plot-sequence", "all", "--out", str(out), "-q"]) == 0
    for i in range(3):
        assert (out / f"roll_pitch_s{i}.png").is_file() and (out / f"roll_pitch_s{i}.svg").is_file()
    assert (out / "error_over_time.png").is_file()  # stays
    assert "roll_pitch_s2.png" in (out / "report.md").read_text()
    first = tmp_path / "first"
    assert main([*map(str, three), "-e", "madgwick", "--out", str(first), "-q"]) == 0
    assert sorted(p.name for p in first.glob("roll_pitch_*.png")) == ["roll_pitch_s0.png"]


def test_roll_pitch_plot_content(three, monkeypatch):
    from riann_ros import evaluation as ev
    from riann_ros.evaluation import plots

    settings = ev.EvalSettings(estimators=ev.parse_estimators("madgwick,vqf"), scenarios=["realistic", "as-recorded"],
                               series_for="*")
    res = ev.evaluate_source(three[1], settings)
    figs = _capture(monkeypatch)
    plots.plot_attitude(res.series, Path("."))
    (stem, fig), = figs
    assert stem == "roll_pitch_s1"
    roll, pitch, err = fig.axes[:3]
    assert (roll.get_ylabel(), pitch.get_ylabel(), err.get_ylabel()) == ("roll (°)", "pitch (°)", "e_α (°)")
    assert [ln.get_label() for ln in roll.lines] == ["reference", "madgwick", "vqf"]
    assert "as-recorded" in roll.get_title()  # the recording as it is, when evaluated
    ref = res.series["attitude"]["as-recorded"]["reference"]
    assert np.nanmax(np.abs(ref[:, 0])) == pytest.approx(25.0, abs=0.5)  # the synthetic roll swings ±25°
    assert np.nanmax(np.abs(ref[:, 1])) < 0.5


def test_roll_pitch_ignore_heading():
    from riann_ros import quaternion as quat
    from riann_ros.evaluation.scoring import roll_pitch_deg

    r, p = np.radians(30.0), np.radians(-20.0)
    q_rp = quat.multiply(quat.from_rotvec([0, p, 0]), quat.from_rotvec([r, 0, 0]))
    for yaw in (0.0, 1.0, -2.5):
        q = quat.multiply(quat.from_rotvec([0, 0, yaw]), q_rp)[None]
        np.testing.assert_allclose(roll_pitch_deg(q), [[30.0, -20.0]], atol=1e-9)


# -- --compare -------------------------------------------------------------------------------------------
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
    assert main(["--compare", str(a), str(b)]) == 0  # as before: the shared labels pair, the others are listed
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


# -- plots: every perturbation condition, fixed colours ---------------------------------------------------
def _svg_ids(path: Path) -> list[str]:
    return re.findall(r'id="((?:panel|estimator):[^"]*)"', path.read_text())


def _svg_colour(path: Path, gid: str) -> str:
    """The first colour (a fill or stroke other than black edges) of the SVG group with this id."""
    text = path.read_text()
    start = text.index(f'id="{gid}"')
    group = text[start:text.index("</g>", start)]
    styles = " ".join(re.findall(r'style="([^"]*)"', group))
    return next(c for c in re.findall(r"(?:stroke|fill): (#[0-9a-f]{6})", styles) if c != "#000000")


@pytest.mark.slow
def test_every_perturbation_condition_is_plotted(three, tmp_path, capsys):
    out = tmp_path / "all"
    args = [*map(str, three[:2]), "-e", "madgwick", "-s", "as-recorded,realistic", "-p", "none", "-p",
            "jitter:10/20/30ms"]
    assert main([*args, "--out", str(out), "-q"]) == 0
    panels = [i for i in _svg_ids(out / "rmse_boxplots.svg") if i.startswith("panel:")]
    assert panels == ["panel:realistic|none", "panel:as-recorded|none", "panel:realistic|jitter:10/20/30ms",
                      "panel:as-recorded|jitter:10/20/30ms"]
    assert sorted(i for i in _svg_ids(out / "error_over_time.svg") if i.startswith("panel:")) == sorted(panels)
    assert (out / "roll_pitch_s0.svg").is_file() and (out / "roll_pitch_s0_jitter_10_20_30ms.svg").is_file()
    assert "roll_pitch_s0_jitter_10_20_30ms.png" in (out / "report.md").read_text()
    chosen = tmp_path / "chosen"  # the user picks the conditions to plot
    assert main([*args, "--plot-perturb", "jitter:10/20/30ms", "--out", str(chosen), "-q"]) == 0
    assert [i for i in _svg_ids(chosen / "rmse_boxplots.svg") if i.startswith("panel:")] == [
        "panel:realistic|jitter:10/20/30ms", "panel:as-recorded|jitter:10/20/30ms"]
    assert sorted(p.name for p in chosen.glob("roll_pitch_*.svg")) == ["roll_pitch_s0_jitter_10_20_30ms.svg"]
    assert main([*args, "--plot-perturb", "jitter:5ms", "--out", str(tmp_path / "x"), "-q"]) == 2
    assert "not an evaluated condition" in capsys.readouterr().err


@pytest.mark.slow
def test_estimator_colours_do_not_depend_on_the_order(three, tmp_path):
    from riann_ros.evaluation import plots

    colours = []
    for order in ("madgwick,vqf,madgwick:beta=0.1", "madgwick:beta=0.1,vqf,madgwick"):
        out = tmp_path / order.replace(":", "_").replace(",", "_")
        assert main([*map(str, three), "-e", order, "-s", "as-recorded", "--out", str(out), "-q"]) == 0
        colours.append({(f.name, e): _svg_colour(out / f.name, f"estimator:{e}")
                        for f in (out / "roll_pitch_s0.svg", out / "rmse_boxplots.svg", out / "error_over_time.svg")
                        for e in ("madgwick", "vqf", "madgwick(beta=0.1)")})
    assert colours[0] == colours[1]
    assert colours[0][("roll_pitch_s0.svg", "madgwick")] == plots.FIXED_COLORS["madgwick"]
    assert colours[0][("rmse_boxplots.svg", "vqf")] == plots.FIXED_COLORS["vqf"]
    assert colours[0][("roll_pitch_s0.svg", "madgwick(beta=0.1)")] not in plots.FIXED_COLORS.values()
