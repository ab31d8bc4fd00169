"""Faults the way users cause them on the installed CLIs: riann-bag-convert interrupted half-way (Ctrl-C) leaves
nothing behind and a rerun succeeds; riann-bag-eval interrupted leaves no result files, keeps the inputs it finished
and --resume completes the run; corrupt bags are named and the good ones still evaluated."""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
from pathlib import Path

import pytest

from conftest import executable, wait_for
from riann_ros import bagio
from riann_ros.datasets.synthetic import generate

# ---- the CLIs interrupted half-way -----------------------------------------------------------------


def _sigint_when(cmd: list[str], cond, timeout: float = 60.0) -> subprocess.CompletedProcess:
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=os.environ.copy())
    try:
        wait_for(lambda: cond() or p.poll() is not None, timeout, "the half-way point")
        assert p.poll() is None, "finished before it could be interrupted: make the input bigger"
        p.send_signal(signal.SIGINT)
        out, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    return subprocess.CompletedProcess(cmd, p.returncode, out, err)


@pytest.mark.slow
def test_converter_interrupted_half_way_leaves_nothing_and_rerun_succeeds(tmp_path):
    out = tmp_path / "out" / "long.mcap"
    # uncompressed (zstd is the default for mcap): the bag grows to ~58 MB, plenty of time after the 4 MB mark
    cmd = [str(executable("riann-bag-convert")), "--format", "synthetic", "--rate", "1000", "--duration", "150",
           "--compression", "none", "-o", str(out)]

    def writing() -> bool:  # the hidden temporary bag exists and has grown: the write is half-way
        return any(f.stat().st_size > 4_000_000 for f in out.parent.glob(".long.mcap.*/**/*.mcap"))

    r = _sigint_when(cmd, writing)
    assert r.returncode == 130, r.stderr
    assert "interrupted" in r.stderr and "Traceback" not in r.stderr
    assert not out.exists()
    assert list(out.parent.iterdir()) == []  # no temporary left either
    r2 = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert r2.returncode == 0, r2.stderr
    assert len(bagio.read_recording(out)) == 150_001


@pytest.fixture(scope="module")
def long_bags(tmp_path_factory) -> list[Path]:
    d = tmp_path_factory.mktemp("long")
    return [bagio.write_recording(d / f"syn{k}.mcap", generate(rate=1000, duration=30, seed=k, start_s=1.0))
            for k in range(3)]


RESULT_FILES = ("results.csv", "results.json", "report.md")


@pytest.mark.slow
@pytest.mark.parametrize("jobs", [1, 2])
def test_evaluator_interrupted_half_way_writes_no_result_files_and_resume_completes(long_bags, tmp_path, jobs):
    out = tmp_path / "eval_out"
    cmd = [str(executable("riann-bag-eval")), *map(str, long_bags), "--estimators", "riann",
           "--scenarios", "realistic", "--jobs", str(jobs), "--out", str(out)]
    err = tmp_path / "stderr.txt"
    p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err.open("w"), env=os.environ.copy(),
                         start_new_session=True)
    try:
        wait_for(lambda: "1/3" in err.read_text() or p.poll() is not None, 120, "the first input done")
        assert p.poll() is None, "finished before it could be interrupted"
        os.killpg(p.pid, signal.SIGINT)  # Ctrl-C in a terminal reaches the whole process group
        p.wait(60)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
    text = err.read_text()
    assert p.returncode != 0
    for f in RESULT_FILES:
        assert not (out / f).exists(), f"{f} left after an interrupted run"
    assert "interrupted" in text and "--resume" in text, text
    kept = len(list((out / "shards").glob("*.npz")))  # the inputs finished before Ctrl-C
    assert kept >= 1
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert again.returncode == 2 and "--resume" in again.stderr  # the same command would mix or lose that run
    r2 = subprocess.run([*cmd, "--resume"], capture_output=True, text=True, timeout=300)
    assert r2.returncode == 0, r2.stderr
    assert f"{kept} of 3 input(s) finished earlier" in r2.stderr
    assert all((out / f).stat().st_size > 0 for f in RESULT_FILES)


# ---- corrupt inputs --------------------------------------------------------------------------------


@pytest.mark.slow
def test_corrupt_bags_are_named_and_the_good_one_still_evaluated(tmp_path):
    from rosbags.rosbag2 import StoragePlugin, Writer

    rec = generate(rate=200, duration=30, seed=4, start_s=1.0)
    good = bagio.write_recording(tmp_path / "good.mcap", rec)
    truncated = tmp_path / "truncated.mcap"
    truncated.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    notable = bagio.write_recording(tmp_path / "notable", rec, storage="sqlite3")
    (db,) = notable.glob("*.db3")
    con = sqlite3.connect(db)
    con.execute("DROP TABLE topics")
    con.commit()
    con.close()
    wrong = tmp_path / "wrongtype"
    ts = bagio.typestore()
    with Writer(wrong, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        c = w.add_connection(bagio.IMU_TOPIC, "std_msgs/msg/String", typestore=ts)
        for t in range(1, 11):
            w.write(c, t * 5_000_000, bytes(ts.serialize_cdr(ts.types["std_msgs/msg/String"](data="imu?"),
                                                             "std_msgs/msg/String")))
    out = tmp_path / "eval_out"
    cmd = [str(executable("riann-bag-eval")), str(truncated), str(notable), str(good), str(wrong),
           "--estimators", "madgwick", "--scenarios", "realistic", "--out", str(out), "--no-plots", "-q"]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert r.returncode == 1, r.stdout + r.stderr
    assert "Traceback" not in r.stderr
    failed = [ln for ln in r.stderr.splitlines() if "FAILED" in ln]
    assert len(failed) == 3, r.stderr
    for bad, why in ((truncated, "truncated"), (notable, "table"), (wrong, "expected sensor_msgs/msg/Imu")):
        line = next((ln for ln in failed if str(bad) in ln), None)
        assert line is not None, f"{bad} not named: {r.stderr}"
        assert why in line.lower() or why in line, line
    assert "1 of 4 input(s) evaluated" in r.stdout
    csv = (out / "results.csv").read_text()
    assert "good" in csv and "truncated" not in csv
