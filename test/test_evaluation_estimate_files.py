"""The estimates as trajectory files (riann_ros.evaluation.estimate_files, --write-estimates): evo's own code on the
TUM files gives the project's total-angle RMSE, and the CSV files read back with --estimate-file score as the
estimators did."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from test_evaluation import synthetic

from riann_ros.cli.evaluate import main
from riann_ros.evaluation.estimate_files import file_stem, parse_formats, safe, write_trajectory

bagio = pytest.importorskip("riann_ros.bagio")
T0 = 1_700_000_000_000_000_000


def test_names_and_formats(tmp_path):
    assert safe("madgwick(beta=0.1)") == "madgwick_beta_0_1"
    assert file_stem("seq a", "as-recorded", "vqf(tau_acc=1) tuned") == "seq_a.as-recorded.vqf_tau_acc_1_tuned"
    assert parse_formats("TUM, csv") == ("tum", "csv")
    with pytest.raises(ValueError, match="tum, csv or tum,csv"):
        parse_formats("kitti")
    # exact decimal seconds; rows without an estimate left out
    q = np.array([[1.0, 0.0, 0.0, 0.0], [np.nan] * 4, [0.0, 0.0, 0.0, -1.0]])
    n = write_trajectory(tmp_path / "x.tum", np.array([T0, T0 + 1, T0 + 10_000_000_123]), q, "tum")
    assert n == 2
    assert (tmp_path / "x.tum").read_text().splitlines()[1:] == [
        "1700000000.000000000 0 0 0 0.000000000 0.000000000 0.000000000 1.000000000",
        "1700000010.000000123 0 0 0 0.000000000 0.000000000 -1.000000000 0.000000000"]


@pytest.fixture(scope="module")
def exported(tmp_path_factory) -> tuple[Path, dict]:
    """A bag (rest, then motion) run with --heading as recorded, estimates written as TUM and CSV files."""
    d = tmp_path_factory.mktemp("export")
    bag = bagio.write_recording(d / "run.mcap", synthetic(name="run", t0_ns=T0, move_s=20.0))
    assert main([str(bag), "-e", "madgwick,vqf", "-s", "as-recorded", "--heading", "--write-estimates", str(d / "est"),
                 "--write-format", "tum,csv", "--out", str(d / "out"), "--no-plots", "-q"]) == 0
    rows = {r["estimator"]: r for r in json.loads((d / "out" / "results.json").read_text())["results"]}
    return d, rows


@pytest.mark.slow
def test_evo_ape_on_the_exported_files_gives_our_total_angle_rmse(exported, tmp_path, monkeypatch):
    """evo's own reader, association and APE (rotation angle, no alignment) on the TUM files: the total-angle RMSE of
    results.json within 0.01° (the reference file holds the scored samples, so evo pairs what we score)."""
    pytest.importorskip("evo")
    monkeypatch.setenv("HOME", str(tmp_path))  # evo keeps its settings in ~/.evo
    from evo.core import metrics, sync
    from evo.tools import file_interface

    d, rows = exported
    est = d / "est"
    ref = file_interface.read_tum_trajectory_file(str(est / "run.as-recorded.reference.tum"))
    for name in ("madgwick", "vqf"):
        traj = file_interface.read_tum_trajectory_file(str(est / f"run.as-recorded.{name}.tum"))
        r, e = sync.associate_trajectories(ref, traj)
        ape = metrics.APE(metrics.PoseRelation.rotation_angle_deg)
        ape.process_data((r, e))
        stats = ape.get_all_statistics()
        assert len(ape.error) == rows[name]["n_scored"]
        for ours, theirs in (("total_rmse_deg", "rmse"), ("total_mean_deg", "mean"), ("total_max_deg", "max"),
                             ("total_std_deg", "std"), ("total_min_deg", "min")):
            assert rows[name][ours] == pytest.approx(stats[theirs], abs=0.01), (name, ours)


@pytest.mark.slow
@pytest.mark.parametrize("fmt", ["csv", "tum"])
def test_files_read_back_score_as_the_estimators(exported, fmt):
    """The CSV files (time[s],qw,qx,qy,qz) and the TUM files (with their comment line) are what --estimate-file
    reads: scored as the estimators they hold."""
    d, rows = exported
    out = d / f"back_{fmt}"
    est = d / "est"
    assert main([str(d / "run.mcap"), "-e", "none", "--estimate-file", f"{est / f'run.as-recorded.madgwick.{fmt}'}:m",
                 "--estimate-file", f"{est / f'run.as-recorded.vqf.{fmt}'}:v", "--out", str(out), "--no-plots",
                 "-q"]) == 0
    back = {r["estimator"]: r for r in json.loads((out / "results.json").read_text())["results"]}
    for label, name in (("m", "madgwick"), ("v", "vqf")):
        assert back[label]["rmse_deg"] == pytest.approx(rows[name]["rmse_deg"], abs=1e-6)
        assert back[label]["n_scored"] == rows[name]["n_scored"]
    header = (est / "run.as-recorded.reference.csv").read_text().splitlines()[0]
    assert header == "time[s],qw,qx,qy,qz"
