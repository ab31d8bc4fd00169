"""Inputs without a reference (riann_ros.evaluation.agreement, scenario_run): every estimator runs as recorded, nothing
is scored, and the run reports the estimators' pairwise agreement, the bias each settled on, the stream's health, an
overlay figure and the estimates as TUM files; offline and over DDS (--live); in a list beside bags with a reference."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from riann_ros import quaternion as quat
from riann_ros.cli.convert import main as convert_main
from riann_ros.cli.evaluate import main
from riann_ros.datasets.synthetic import generate
from riann_ros.evaluation.agreement import WINDOW_S, Agreement

bagio = pytest.importorskip("riann_ros.bagio")
ESTIMATORS = ("riann", "madgwick", "mahony", "vqf")


def test_agreement_figures_and_where_the_estimators_part():
    """Two estimates that differ by a known tilt: RMS, mean, max, time of the max and the windows where they part,
    whatever the chunking; a third that gives no estimate half the time is compared where it gives one."""
    n, rate = 3000, 100.0
    stamps = 5_000_000_000 + (np.arange(n) * 1e9 / rate).astype(np.int64)
    tilt = np.full(n, 1.0)
    tilt[1200:1300] = 4.0  # they part most from 12 to 13 s
    tilt[2500] = 7.0  # the largest difference, at 25 s
    base = quat.from_rotvec(np.column_stack([np.zeros(n), np.zeros(n), np.linspace(0, 3, n)]))  # a turn: no effect
    a = base
    b = quat.multiply(base, quat.from_rotvec(np.column_stack([np.radians(tilt), np.zeros(n), np.zeros(n)])))
    c = a.copy()
    c[::2] = np.nan
    for chunk in (n, 700):
        ag = Agreement(["a", "b", "c"], int(stamps[0]))
        for k in range(0, n, chunk):
            ag.add(stamps[k:k + chunk], [a[k:k + chunk], b[k:k + chunk], c[k:k + chunk]])
        ab, ac, bc = ag.result()
        assert (ab["a"], ab["b"], ab["n"]) == ("a", "b", n)
        assert ab["rms_deg"] == pytest.approx(np.sqrt(np.mean(tilt**2)), abs=1e-6)
        assert ab["mean_deg"] == pytest.approx(tilt.mean(), abs=1e-6)
        assert ab["max_deg"] == pytest.approx(7.0, abs=1e-6) and ab["t_max_s"] == pytest.approx(25.0)
        assert ab["parts"][0] == {"start_s": 12.0, "end_s": 12.0 + WINDOW_S, "rms_deg": pytest.approx(4.0)}
        assert ab["parts"][1]["start_s"] == 25.0
        assert ac["n"] == n // 2 and ac["rms_deg"] == pytest.approx(0.0, abs=1e-6)
        assert bc["n"] == n // 2
        assert list(ag.n_estimated) == [n, n, n // 2]


def _csv_without_reference(path: Path, seconds: float = 30.0) -> Path:
    """The synthetic generator's IMU columns (rest, then motion) as a CSV without reference columns."""
    rec = generate(motion="combined", rate=100.0, duration=seconds, seed=4)
    rows = np.column_stack([rec.t, rec.acc, rec.gyr])
    np.savetxt(path, rows, delimiter=",", header="t,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z", comments="", fmt="%.9f")
    return path


@pytest.fixture(scope="module")
def robot(tmp_path_factory) -> Path:
    """A bag converted from a CSV without reference columns (a robot's own recording)."""
    d = tmp_path_factory.mktemp("robot")
    csv_file = _csv_without_reference(d / "robot.csv")
    assert convert_main([str(csv_file), "-o", str(d / "robot.mcap"), "-q"]) == 0
    return d / "robot.mcap"


def _check_free_run(out: Path, est: Path, mode: str) -> dict:
    """What a run without a reference writes: a TUM file per estimator (no reference file), the overlay figure, and
    results.json with one unscored row per estimator and the agreement of every pair."""
    tums = sorted(p.name for p in est.glob("*.tum"))
    assert tums == sorted(f"robot.as-recorded.{e}.tum" for e in ESTIMATORS)
    assert (est / "robot.mcap").is_file()
    lines = (est / "robot.as-recorded.riann.tum").read_text().splitlines()
    assert lines[0].startswith("#") and len(lines[1].split()) == 8 and lines[1].split()[1:4] == ["0", "0", "0"]
    assert (out / "attitude_robot.png").is_file() and (out / "attitude_robot.svg").is_file()
    data = json.loads((out / "results.json").read_text())
    seq = data["sequences"][0]
    assert seq["has_reference"] is False and seq["name"] == "robot"
    rows = data["results"]
    assert [r["estimator"] for r in rows] == list(ESTIMATORS)
    assert all(r["has_reference"] is False and r["rmse_deg"] is None and r["n_scored"] == 0 for r in rows)
    assert all(r["mode"] == mode and r["scenario"] == "as-recorded" for r in rows)
    pairs = {(p["a"], p["b"]): p for p in seq["agreement"]}
    assert len(pairs) == 6
    for p in pairs.values():
        assert p["n"] > 2000 and 0.0 <= p["rms_deg"] <= p["max_deg"] < 30.0
        assert 0.0 <= p["t_max_s"] <= 31.0 and 1 <= len(p["parts"]) <= 3
    assert data["summary"] == []
    return data


@pytest.mark.slow
def test_a_bag_without_reference_is_run_by_every_estimator(robot, tmp_path, capsys):
    out, est = tmp_path / "out", tmp_path / "est"
    rc = main([str(robot), "-e", ",".join(ESTIMATORS), "--write-estimates", str(est), "--out", str(out), "-q"])
    assert rc == 0
    text = capsys.readouterr().out
    data = _check_free_run(out, est, "offline")
    assert "FAILED" not in text and "without a reference (agreement, bias, health only): robot" in text
    assert "agreement without a reference" in text and "riann – vqf" in text and "stream health" in text
    assert "(1 without a reference: not scored)" in text
    # the bias each settled on beside the gyro at the recording's rest (the generator's rest, its true bias)
    rows = {r["estimator"]: r for r in data["results"]}
    rests = data["sequences"][0]["health"]["rests"]
    assert rests and rests[0]["start_s"] < 1.0
    for name in ("riann", "vqf"):
        bias = [rows[name][f"gyro_bias_{a}_dps"] for a in "xyz"]
        assert np.allclose(bias, rests[0]["gyr_mean_dps"], atol=0.15), (name, bias, rests[0])
    assert rows["madgwick"].get("gyro_bias_x_dps") is None  # Madgwick reports no bias estimate by default
    health = data["sequences"][0]["health"]
    assert health["rate_hz"] == pytest.approx(100.0) and health["holes"] == 0 and health["rejected"] == {}
    md = (out / "report.md").read_text()
    assert "## Without a reference" in md and "## Stream health" in md and "![attitude_robot]" in md


@pytest.mark.slow
def test_a_list_mixing_bags_with_and_without_reference_says_which_is_which(robot, tmp_path, capsys):
    rec = generate(motion="rotation", rate=100.0, duration=20.0, seed=5)
    scored = bagio.write_recording(tmp_path / "scored.mcap", rec)
    out = tmp_path / "out"
    assert main([str(scored), str(robot), "-e", "madgwick,vqf", "--out", str(out), "--no-plots", "-q"]) == 0
    text = capsys.readouterr().out
    assert f"with a reference (scored): {rec.name}; without a reference (agreement, bias, health only): robot" in text
    data = json.loads((out / "results.json").read_text())
    assert [s["has_reference"] for s in data["sequences"]] == [True, False]
    assert {g["estimator"] for g in data["summary"]} == {"madgwick", "vqf"}  # from the scored bag alone
    assert all(g["n"] == 1 for g in data["summary"])
    table = list(csv.DictReader((out / "results.csv").open()))
    assert {(r["sequence"], r["has_reference"]) for r in table} == {(rec.name, "True"), ("robot", "False")}
    assert all(r["rmse_deg"] == "nan" and r["n_scored"] == "0" for r in table if r["sequence"] == "robot")
    assert f"Inputs with a reference (scored): {rec.name}; without" in (out / "report.md").read_text()


@pytest.mark.ros
@pytest.mark.slow
def test_a_bag_without_reference_live(robot, tmp_path, capsys):
    """The same over DDS to the installed nodes (--live), estimates exported."""
    pytest.importorskip("rclpy")
    out, est = tmp_path / "out", tmp_path / "est"
    rc = main([str(robot), "-e", ",".join(ESTIMATORS), "--live", "--speed", "0", "--write-estimates", str(est),
               "--out", str(out), "-q"])
    assert rc == 0, capsys.readouterr().err
    data = _check_free_run(out, est, "live")
    assert all(r["lost"] == 0 for r in data["results"])
    # live and offline give the same agreement (the nodes run the same code)
    off = tmp_path / "off"
    assert main([str(robot), "-e", ",".join(ESTIMATORS), "--out", str(off), "--no-plots", "-q"]) == 0
    offline = json.loads((off / "results.json").read_text())["sequences"][0]["agreement"]
    for a, b in zip(offline, data["sequences"][0]["agreement"], strict=True):
        assert (a["a"], a["b"]) == (b["a"], b["b"])
        assert b["rms_deg"] == pytest.approx(a["rms_deg"], abs=0.01)
