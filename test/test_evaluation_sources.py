"""Inputs of riann-bag-eval beyond the project's own bags (riann_ros.evaluation.sources): estimates in TUM and CSV
trajectory files (--estimate-file) scored with evo ape's error statistics and the best time offset, their errors,
and inputs that are not bags (a CSV file, an EuRoC folder, a folder of dataset files, a ROS 1 bag) answered with
the commands that convert them."""

from __future__ import annotations

import csv
import json
import shlex
from pathlib import Path

import numpy as np
import pytest
from test_evaluation import synthetic

from riann_ros import quaternion as quat
from riann_ros.cli.convert import main as convert_main
from riann_ros.cli.evaluate import main

bagio = pytest.importorskip("riann_ros.bagio")

T0 = 1_700_000_000_000_000_000
LATE_S = 0.015  # the CSV estimate is the reference stamped this much late


def _rows(out: Path) -> dict[str, dict]:
    return {r["estimator"]: r for r in json.loads((out / "results.json").read_text())["results"]}


# -- --estimate-file, evo ape's statistics, the best time offset --------------------------------------------
@pytest.fixture(scope="module")
def run1(tmp_path_factory) -> tuple[Path, np.ndarray]:
    """A bag, a TUM file holding its reference tilted about x by 0.5° → 3° over the recording, and a CSV file
    holding its reference stamped LATE_S late; returns the folder and the tilt (°) at the scored samples."""
    d = tmp_path_factory.mktemp("evo")
    rec = synthetic(name="run1", t0_ns=T0)
    bagio.write_recording(d / "run1.mcap", rec)
    n = len(rec)
    tilt = np.radians(np.linspace(0.5, 3.0, n))
    q = quat.multiply(rec.quat_ref, quat.from_rotvec(np.column_stack([tilt, np.zeros(n), np.zeros(n)])))
    t = rec.stamps_ns * 1e-9
    with (d / "run1_tilt.tum").open("w") as f:  # t tx ty tz qx qy qz qw, seconds
        for ti, (w, x, y, z) in zip(t, q, strict=True):
            f.write(f"{ti:.9f} 0 0 0 {x:.9f} {y:.9f} {z:.9f} {w:.9f}\n")
    with (d / "run1_late.csv").open("w") as f:
        f.write("time[s],qw,qx,qy,qz\n")
        for ti, (w, x, y, z) in zip(t + LATE_S, rec.quat_ref, strict=True):
            f.write(f"{ti:.9f},{w:.9f},{x:.9f},{y:.9f},{z:.9f}\n")
    return d, np.degrees(tilt)[rec.score_mask]


@pytest.mark.slow
def test_estimate_files_are_scored_with_evo_statistics(run1, capsys):
    d, tilt = run1
    out = d / "out"
    assert main([str(d / "run1.mcap"), "--estimate-file", f"{d / 'run1_tilt.tum'}:tilt", "--estimate-file",
                 str(d / "run1_late.csv"), "-e", "madgwick", "-s", "as-recorded", "--out", str(out), "-q"]) == 0
    text = capsys.readouterr().out
    rows = _rows(out)
    assert set(rows) == {"madgwick", "tilt", "run1_late"}  # the CSV's label: its file name
    r = rows["tilt"]  # the error of each sample is the tilt: evo ape's statistics of it
    assert r["n_scored"] == len(tilt)
    for key, want in [("rmse_deg", np.sqrt(np.mean(tilt**2))), ("mean_err_deg", tilt.mean()),
                      ("std_err_deg", tilt.std()), ("min_err_deg", tilt.min()), ("max_err_deg", tilt.max())]:
        assert r[key] == pytest.approx(want, abs=1e-4), key
    assert r["median_err_deg"] == pytest.approx(np.median(tilt), rel=5e-3)  # a histogram's median: bins 0.2 % wide
    # the late estimate: best moved by -LATE_S, where it is the reference itself
    late = rows["run1_late"]
    assert late["rmse_deg"] > 0.2
    assert late["best_t_offset_s"] == pytest.approx(-LATE_S, abs=5e-4)
    assert late["best_t_offset_rmse_deg"] < 0.02 and late["t_offset_step_s"] == pytest.approx(0.01)
    # the same columns in results.csv and in the printed table
    row = next(x for x in csv.DictReader((out / "results.csv").open()) if x["estimator"] == "tilt")
    assert float(row["median_err_deg"]) == pytest.approx(r["median_err_deg"], abs=1e-5)
    line = next(x for x in text.splitlines() if x.startswith("run1") and " tilt " in x).split()
    assert line[3:9] == [f"{v:.2f}" for v in (r["rmse_deg"], r["mean_err_deg"], r["median_err_deg"],
                                             r["std_err_deg"])] + [f"{r['min_err_deg']:.3f}", f"{r['max_err_deg']:.2f}"]
    assert "best offset ms" in text and "rmse there" in text
    # --t-offset moves a file's stamps as the search said: then it scores as the reference
    out2 = d / "moved"
    assert main([str(d / "run1.mcap"), "--estimate-file", f"{d / 'run1_late.csv'}:late", "--t-offset", str(-LATE_S),
                 "-e", "vqf", "-s", "as-recorded", "--out", str(out2), "--no-plots", "-q"]) == 0
    moved = _rows(out2)["late"]
    assert moved["rmse_deg"] < 0.02 and moved["best_t_offset_s"] == pytest.approx(0.0, abs=5e-4)


def test_estimate_file_errors(run1, tmp_path, capsys):
    d, _ = run1
    bag = str(d / "run1.mcap")
    assert main([bag, "--estimate-file", str(tmp_path / "none.tum"), "--no-plots", "-q"]) == 2
    assert "estimate file" in (err := capsys.readouterr().err) and "none.tum" in err
    (tmp_path / "bad.csv").write_text("a,b\n1,2\n")
    assert main([bag, "--estimate-file", str(tmp_path / "bad.csv"), "--no-plots", "-q"]) == 2
    assert "--estimate-cols" in capsys.readouterr().err
    # stamps from 0 (not the bag's clock): no estimate meets a sample, the message says how to move them
    rel = tmp_path / "rel.tum"
    rel.write_text("".join(f"{float(ln.split()[0]) - T0 * 1e-9:.6f} {' '.join(ln.split()[1:])}\n"
                           for ln in (d / "run1_tilt.tum").read_text().splitlines()))
    assert main([bag, "--estimate-file", str(rel), "-s", "as-recorded", "--no-plots", "-q"]) == 1
    assert "no estimate near any scored sample" in (err := capsys.readouterr().err) and "--t-offset" in err


# -- inputs that are not bags: the message gives the commands that convert them ------------------------


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
