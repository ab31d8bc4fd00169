"""The time offset found for the user (riann_ros.evaluation.offsets): RIANN's best offset follows a reference
shifted in time, and near half a step the timing note points at the sample-time convention."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from test_evaluation import synthetic

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
