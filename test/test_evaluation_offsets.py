"""The time offset found for the user (riann_ros.evaluation.offsets): RIANN's best offset follows a reference
shifted in time, and near half a step the timing note points at the sample-time convention; a still recording gets
no note, and a note reads the same whatever other estimators run."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from test_evaluation import synthetic

from riann_ros import quaternion as quat
from riann_ros.cli.evaluate import main
from riann_ros.recording import Recording

bagio = pytest.importorskip("riann_ros.bagio")

T0 = 1_700_000_000_000_000_000


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


def _notes(text: str) -> list[str]:
    return [x.removeprefix("timing: ") for x in text.split("\n\n") if x.startswith("timing:")]


@pytest.mark.slow
def test_a_still_recording_claims_no_offset(tmp_path, capsys):
    """On a sensor that does not move every offset fits alike: the search's best is noise (often at the edge), and
    no note claims it."""
    rng = np.random.default_rng(3)
    n = 2000
    stamps = T0 + np.arange(n, dtype=np.int64) * 10_000_000
    ref = quat.from_rotvec(np.radians([1.0, -0.5, 30.0]) + rng.normal(0, np.radians(0.03), (n, 3)))
    acc = quat.rotate(quat.conjugate(ref), np.array([0.0, 0.0, 9.81])) + rng.normal(0, 0.03, (n, 3))
    gyr = np.radians([0.3, -0.2, 0.1]) + rng.normal(0, np.radians(0.05), (n, 3))
    bag = bagio.write_recording(tmp_path / "still.mcap", Recording(stamps, acc, gyr, ref, name="still",
                                                                   dataset="synth"))
    out = tmp_path / "out"
    assert main([str(bag), "-s", "as-recorded", "--out", str(out), "--no-plots", "-q"]) == 0
    assert _notes(capsys.readouterr().out) == []
    data = json.loads((out / "results.json").read_text())
    assert data["timing_notes"] == []
    for r in data["results"]:
        assert r["best_t_offset_s"] is not None and r["t_offset_ref_turn_dps"] < 2.0


@pytest.mark.slow
def test_a_note_reads_the_same_whatever_else_runs(shifted, capsys):
    """RIANN's note on the bag whose reference is 15 ms ahead is the same alone and beside other estimators."""
    args = [str(shifted[15]), "-s", "as-recorded", "--no-plots", "-q"]
    assert main([*args, "-e", "riann:input_model=points"]) == 0
    alone = _notes(capsys.readouterr().out)
    assert main([*args, "-e", "madgwick,riann:input_model=points,vqf"]) == 0
    beside = _notes(capsys.readouterr().out)
    assert len(alone) == 1 and alone[0] in beside
