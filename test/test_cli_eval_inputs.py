"""What riann-bag-eval reads besides the bags (riann_ros.cli.eval_inputs): one --estimate-file label over a glob or a
folder of trajectory files, each file matched to its input by name, scored as one estimator over the inputs."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from test_evaluation import synthetic

from riann_ros import quaternion as quat
from riann_ros.cli.eval_inputs import owner
from riann_ros.cli.evaluate import main

bagio = pytest.importorskip("riann_ros.bagio")
T0 = 1_700_000_000_000_000_000
TILTS = {"run1": 1.0, "run2": 2.0, "run10": 3.0}  # each file's estimate: the reference tilted by this many degrees


def test_a_file_belongs_to_the_input_whose_stem_starts_its_stem():
    inputs = ["bags/run1.mcap", "bags/run10.mcap", "bags/run1_b.mcap", "other/run2"]
    assert owner("est/run1.tum", inputs) == "bags/run1.mcap"
    assert owner("est/run1_vins.tum", inputs) == "bags/run1.mcap"
    assert owner("est/run10-fusion.csv", inputs) == "bags/run10.mcap"
    assert owner("est/run1_b_fusion.tum", inputs) == "bags/run1_b.mcap"  # the longest stem
    assert owner("est/run2.tum", inputs) == "other/run2"  # a bag directory: its name
    assert owner("est/run100.tum", inputs) is None  # run1 followed by a digit: another run
    assert owner("est/walk.tum", inputs) is None


@pytest.fixture(scope="module")
def corpus(tmp_path_factory) -> Path:
    """Bags run1, run2, run10, run3; a folder est/ with a TUM file per bag but run3, and one of no bag."""
    d = tmp_path_factory.mktemp("corpus")
    (d / "est").mkdir()
    for name in ("run1", "run2", "run10", "run3"):
        rec = synthetic(name=name, t0_ns=T0)
        bagio.write_recording(d / f"{name}.mcap", rec)
        if name not in TILTS:
            continue
        n = len(rec)
        q = quat.multiply(rec.quat_ref, quat.from_rotvec(np.column_stack(
            [np.full(n, np.radians(TILTS[name])), np.zeros(n), np.zeros(n)])))
        suffix = "_fusion" if name == "run2" else ""
        with (d / "est" / f"{name}{suffix}.tum").open("w") as f:
            f.writelines(f"{t * 1e-9:.9f} 0 0 0 {x:.9f} {y:.9f} {z:.9f} {w:.9f}\n"
                         for t, (w, x, y, z) in zip(rec.stamps_ns, q, strict=True))
    (d / "est" / "stray.tum").write_text((d / "est" / "run1.tum").read_text())
    return d


@pytest.mark.parametrize("form", ["folder", "glob"])
def test_one_label_over_a_folder_or_glob_scores_one_estimator(corpus, tmp_path, capsys, form):
    bags = [str(corpus / f"{n}.mcap") for n in ("run1", "run2", "run10", "run3")]
    files = f"{corpus / 'est'}:fusion" if form == "folder" else f"{corpus / 'est' / 'r*.tum'}:fusion"
    out = tmp_path / "out"
    assert main([*bags, "-e", "none", "--estimate-file", files, "--out", str(out), "--no-plots", "-q"]) == 0
    err = capsys.readouterr().err
    assert f"warning: --estimate-file fusion: no file in {corpus / 'est'}" in err and f"for input {bags[3]}" in err
    assert ("stray.tum belongs to no input" in err) == (form == "folder")
    data = json.loads((out / "results.json").read_text())
    rows = {r["sequence"]: r for r in data["results"]}
    assert set(rows) == set(TILTS) and {r["estimator"] for r in rows.values()} == {"fusion"}
    for name, tilt in TILTS.items():
        assert rows[name]["rmse_deg"] == pytest.approx(tilt, abs=1e-4)
    (group,) = data["summary"]
    assert (group["estimator"], group["n"]) == ("fusion", 3) and group["mean"] == pytest.approx(2.0, abs=1e-4)
    assert any("no file in" in w for w in data["settings"]["input_warnings"])


def test_estimate_file_label_errors(corpus, tmp_path, capsys):
    bags = [str(corpus / "run1.mcap"), str(corpus / "run2.mcap")]
    assert main([*bags, "--estimate-file", str(corpus / "est" / "*.tum"), "-q"]) == 2
    assert "give the files of a glob or folder one label" in capsys.readouterr().err
    # two files of one label for one input
    assert main([*bags, "--estimate-file", f"{corpus / 'est' / 'run1.tum'}:f",
                 "--estimate-file", f"{corpus / 'est' / 'stray.tum'}:f", "-q"]) == 2
    err = capsys.readouterr().err
    assert "stray.tum" in err and "none of" in err  # a single named file must belong to an input
    assert main([bags[0], "--estimate-file", f"{corpus / 'est' / 'run1.tum'}:f",
                 "--estimate-file", f"{corpus / 'est' / 'r*.tum'}:f", "-q"]) == 2
    assert "estimate label 'f' given twice for input" in capsys.readouterr().err
    assert main([*bags, "--estimate-file", f"{corpus / 'est' / 'nothing*.tum'}:f", "-q"]) == 2
    assert "no trajectory file there" in capsys.readouterr().err
