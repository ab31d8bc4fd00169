"""riann-bag-eval's --out policy (riann_ros.evaluation.outdir): an earlier run in the folder is never lost silently;
--force replaces only the result files, the user's own files stay."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from test_evaluation import synthetic

from riann_ros.cli.evaluate import main
from riann_ros.evaluation import outdir

bagio = pytest.importorskip("riann_ros.bagio")


@pytest.fixture(scope="module")
def bag(tmp_path_factory) -> Path:
    rec = synthetic(name="seq", t0_ns=1_700_000_000_000_000_000)
    return bagio.write_recording(tmp_path_factory.mktemp("files") / "seq.mcap", rec)


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


def test_an_output_folder_is_checked_for_kind_and_write_permission(tmp_path):
    from helpers_fs import read_only

    outdir.check_folder(tmp_path / "new" / "deeper", "--out")  # made later, under a writable folder
    assert not (tmp_path / "new").exists() and list(tmp_path.iterdir()) == []  # the try left nothing
    (tmp_path / "file").write_text("")
    with pytest.raises(ValueError, match=r"^--out .*file: exists and is not a folder$"):
        outdir.check_folder(tmp_path / "file", "--out")
    with pytest.raises(ValueError, match=r"file is not a folder$"):
        outdir.check_folder(tmp_path / "file" / "below", "--out")
    with pytest.raises(ValueError, match=r"is a folder, not a file$"):
        outdir.check_file(tmp_path, "--out")
    with read_only(tmp_path / "locked") as locked:
        with pytest.raises(ValueError, match=rf"^--plots {locked}/x: cannot write into {locked}: "):
            outdir.check_folder(locked / "x", "--plots")
        with pytest.raises(ValueError, match=rf"^--out {locked}/cal.yaml: cannot write into {locked}: "):
            outdir.check_file(locked / "cal.yaml", "--out")
