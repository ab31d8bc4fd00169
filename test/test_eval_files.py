"""riann-bag-eval's files: the --out policy (an earlier run is never lost silently) and inputs to convert first."""

from __future__ import annotations

import json
import shlex
from pathlib import Path

import numpy as np
import pytest
from test_evaluation import synthetic

from riann_ros.cli.convert import main as convert_main
from riann_ros.cli.evaluate import main
from riann_ros.evaluation import report

bagio = pytest.importorskip("riann_ros.bagio")


@pytest.fixture(scope="module")
def bag(tmp_path_factory) -> Path:
    rec = synthetic(name="seq", t0_ns=1_700_000_000_000_000_000)
    return bagio.write_recording(tmp_path_factory.mktemp("files") / "seq.mcap", rec)


# -- --out ----------------------------------------------------------------------------------------------
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
    assert report.previous_results(tmp_path / "nothing_here") == []


def test_prepare_out_api(tmp_path):
    (tmp_path / "results.csv").write_text("old")
    (tmp_path / "keep.csv").write_text("mine")
    with pytest.raises(report.OutputExists, match="--force"):
        report.prepare_out(tmp_path, replace=False)
    assert report.prepare_out(tmp_path, replace=True) == [tmp_path / "results.csv"]
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
