"""riann-bag-eval's evo habits, run as a user runs them on bags written by the project's writer: estimates in TUM
and CSV trajectory files (--estimate-file), evo ape's error statistics, the time offset found for the user (and the
note on the sample-time convention), and bags cut off by a crash (--salvage, riann-bag-convert --repair)."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from test_evaluation import synthetic

from riann_ros import quaternion as quat
from riann_ros.cli.convert import main as convert_main
from riann_ros.cli.evaluate import main
from riann_ros.recording import Recording

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


@pytest.fixture(scope="module")
def shifted(tmp_path_factory) -> dict[int, Path]:
    """50 Hz bags (from a 1 kHz synthetic recording) whose reference is ahead of the IMU by 0 and 15 ms."""
    d = tmp_path_factory.mktemp("shift")
    r = synthetic(rate=1000.0, move_s=18.0, name="x", t0_ns=T0)
    n = (len(r) - 40) // 20 * 20
    out = {}
    for k in (0, 15):
        imu, ref = slice(0, n, 20), slice(k, n + k, 20)
        rec = Recording(r.stamps_ns[imu], r.acc[imu], r.gyr[imu], r.quat_ref[ref], r.score_mask[imu],
                        name=f"ahead{k}ms", dataset="synth")
        out[k] = bagio.write_recording(d / f"ahead{k}ms.mcap", rec)
    return out


@pytest.mark.slow
def test_best_offset_and_the_sample_time_note(shifted, tmp_path, capsys):
    """RIANN's best offset follows the reference's shift; near half a step it points at the sample-time setting.
    The bags hold point samples, so RIANN is told so (at its default it would read them a quarter step early)."""
    out = tmp_path / "out"
    assert main([str(shifted[0]), str(shifted[15]), "-e", "riann:input_model=points", "-s", "as-recorded", "--out",
                 str(out), "--no-plots"]) == 0
    text = capsys.readouterr().out
    rows = {(r["sequence"]): r for r in json.loads((out / "results.json").read_text())["results"]}
    a, b = rows["ahead0ms"], rows["ahead15ms"]
    assert b["best_t_offset_s"] - a["best_t_offset_s"] == pytest.approx(-0.015, abs=1e-3)
    # aligned: the network's own lead on ideal samples, about 5 ms (docs/riann.md, stage 2), short of half a step
    assert a["best_t_offset_s"] == pytest.approx(0.005, abs=0.002)
    assert b["best_t_offset_rmse_deg"] < 0.9 * b["rmse_deg"]
    notes = [x for x in text.split("\n\n") if x.startswith("timing:")]
    assert len(notes) == 1 and notes[0].startswith("timing: ahead15ms, as-recorded: riann")
    assert "sample-time convention" in notes[0] and "input_model" in notes[0] and "docs/riann.md" in notes[0]
    assert "sample_delay" in notes[0]
    assert "- " + notes[0].removeprefix("timing: ") in (out / "report.md").read_text().split("## Timing")[1]
    # --offset-steps 0: no search, no columns
    assert main([str(shifted[15]), "-e", "riann", "-s", "as-recorded", "--offset-steps", "0", "--no-plots"]) == 0
    text = capsys.readouterr().out
    assert "best offset ms" not in text and "timing:" not in text


# -- truncated bags --------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def long_rec() -> Recording:
    return synthetic(name="long", move_s=40.0, t0_ns=T0)  # 4,200 samples: an MCAP file of several chunks


def _cut(src: Path, dst: Path, fraction: float) -> Path:
    data = src.read_bytes()
    dst.write_bytes(data[: int(len(data) * fraction)])  # head -c N src > dst
    return dst


def _imu_count(err: str) -> int:
    """The readable IMU messages a message reports ('2,346 /imu/data_raw')."""
    word = next(w for w in err.replace("(", " ").split(", ") if w.endswith(" /imu/data_raw"))
    return int(word.split()[-2].replace(",", ""))


@pytest.mark.slow
def test_truncated_mcap(long_rec, tmp_path, capsys):
    whole = bagio.write_recording(tmp_path / "long.mcap", long_rec)
    cut = _cut(whole, tmp_path / "cut.mcap", 0.6)
    args = ["-e", "madgwick", "-s", "as-recorded", "--no-plots", "--offset-steps", "0"]
    assert main([str(cut), *args, "-q"]) == 1
    err = capsys.readouterr().err
    assert "truncated" in err and f"ends at byte {cut.stat().st_size:,}" in err and "of 4,200 IMU samples" in err
    assert "--salvage" in err and f"riann-bag-convert --repair {cut} -o {tmp_path / 'cut_repaired.mcap'}" in err
    n = _imu_count(err)
    assert 1000 < n < 4200 * 0.6
    # --salvage: the readable part is scored, with a warning and the counts in results.json
    out = tmp_path / "salvaged"
    assert main([str(cut), *args, "--salvage", "--out", str(out), "-q"]) == 0
    assert "salvaged: truncated" in capsys.readouterr().err
    data = json.loads((out / "results.json").read_text())
    (seq,) = data["sequences"]
    assert seq["salvaged"]["messages_per_topic"]["/imu/data_raw"] == n
    assert seq["salvaged"]["imu_samples_recorded"] == 4200 and seq["salvaged"]["file_bytes"] == cut.stat().st_size
    (row,) = data["results"]
    assert row["n_samples"] == n and row["source"] == str(cut)
    # riann-bag-convert --repair: a complete bag of the same messages; the output is never overwritten silently
    fixed = tmp_path / "fixed.mcap"
    assert convert_main(["--repair", str(cut), "-o", str(fixed)]) == 0
    assert f"{n:,} /imu/data_raw" in capsys.readouterr().err
    rec = bagio.read_recording(fixed)
    assert len(rec) == n
    np.testing.assert_array_equal(rec.stamps_ns, long_rec.stamps_ns[:n])
    np.testing.assert_allclose(rec.gyr, long_rec.gyr[:n], atol=1e-12)
    before = fixed.read_bytes()
    assert convert_main(["--repair", str(cut), "-o", str(fixed)]) == 1
    assert "exists" in capsys.readouterr().err and fixed.read_bytes() == before
    assert convert_main(["--repair", str(cut), "-o", str(fixed), "--force"]) == 0
    again = tmp_path / "again"
    assert main([str(fixed), *args, "--out", str(again), "-q"]) == 0
    assert _rows(again)["madgwick"]["rmse_deg"] == pytest.approx(row["rmse_deg"], abs=1e-9)
    # a complete bag is not 'repaired'
    assert convert_main(["--repair", str(whole), "-o", str(tmp_path / "x.mcap")]) == 1
    assert "not truncated" in capsys.readouterr().err and not (tmp_path / "x.mcap").exists()


def test_truncated_mcap_with_nothing_readable(long_rec, tmp_path, capsys):
    whole = bagio.write_recording(tmp_path / "long.mcap", long_rec)
    cut = _cut(whole, tmp_path / "cut.mcap", 0.1)  # inside the first chunk
    assert main([str(cut), "-e", "madgwick", "--salvage", "--no-plots", "-q"]) == 1
    err = capsys.readouterr().err
    assert "truncated" in err and "no message before the cut is readable" in err


def test_truncated_sqlite3(long_rec, tmp_path, capsys):
    whole = bagio.write_recording(tmp_path / "long", long_rec, storage="sqlite3")
    cut_dir = tmp_path / "cut"
    cut_dir.mkdir()
    (cut_dir / "metadata.yaml").write_text((whole / "metadata.yaml").read_text())
    _cut(whole / "long.db3", cut_dir / "long.db3", 0.6)
    args = ["-e", "madgwick", "-s", "as-recorded", "--no-plots", "--offset-steps", "0", "-q"]
    assert main([str(cut_dir), *args]) == 1
    err = capsys.readouterr().err
    assert "truncated" in err and "where its header says" in err and "--salvage" in err
    n = _imu_count(err)
    assert 1000 < n < 4200 * 0.6
    out = tmp_path / "salvaged"
    assert main([str(cut_dir), *args, "--salvage", "--out", str(out)]) == 0
    assert _rows(out)["madgwick"]["n_samples"] == n
    fixed = tmp_path / "fixed"
    assert convert_main(["--repair", str(cut_dir), "-o", str(fixed)]) == 0
    assert bagio.bag_storage(fixed) == "sqlite3"
    rec = bagio.read_recording(fixed)
    assert len(rec) == n
    np.testing.assert_array_equal(rec.stamps_ns, long_rec.stamps_ns[:n])
