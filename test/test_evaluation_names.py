"""Every input prints under a name of its own (riann_ros.evaluation.names): bags converted from one CSV file carry
one recorded name; they are named after their files, with a warning, and score as they do alone."""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_evaluation import synthetic

from riann_ros.cli.convert import main as convert_main
from riann_ros.cli.evaluate import main
from riann_ros.evaluation.names import unique_names
from riann_ros.evaluation.results import SequenceResult


def test_clashing_names_take_the_file_then_the_folder_then_a_number():
    def res(name: str, source: str) -> SequenceResult:
        return SequenceResult(source=source, name=name, warnings=[f"{name}: no rest found"])

    results = [res("x", "a/one.mcap"), res("x", "b/two.mcap"), res("y", "c/y.mcap"), res("z", "d/s.mcap"),
               res("z", "e/s.mcap"), res("w", "f/w.mcap"), res("w", "f/w.mcap"),
               SequenceResult(source="bad.mcap", error="bad")]
    warnings = unique_names(results)
    assert [r.name for r in results[:7]] == ["one", "two", "y", "d/s", "e/s", "f/w#1", "f/w#2"]
    assert [r.recorded_name for r in results[:7]] == ["x", "x", "", "z", "z", "w", "w"]
    assert len(warnings) == 6
    assert results[0].warnings[0].startswith("one: named after its file a/one.mcap: the recorded name x is also "
                                             "b/two.mcap's")
    assert results[0].warnings[1] == "one: no rest found"  # the input's own warnings follow its new name
    assert results[2].warnings == ["y: no rest found"]
    assert unique_names(results) == []  # nothing left to rename


@pytest.mark.slow
def test_two_bags_from_one_csv_score_as_two_names(tmp_path, capsys):
    rec = synthetic(name="ignored", move_s=10.0)
    csv = tmp_path / "rest20_g_dps.csv"
    rows = np.column_stack([rec.t, rec.acc, rec.gyr, rec.quat_ref, rec.score_mask.astype(int)])
    np.savetxt(csv, rows, delimiter=",", header="t,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z,qw,qx,qy,qz,scored",
               comments="", fmt="%.12g")
    for d in ("a", "b"):
        (tmp_path / d).mkdir()
    assert convert_main([str(csv), "-o", str(tmp_path / "a" / "first.mcap"), "-q"]) == 0
    assert convert_main([str(csv), "-o", str(tmp_path / "b" / "second.mcap"), "-q"]) == 0
    out = tmp_path / "out"
    args = ["-e", "madgwick", "-s", "realistic", "--no-plots", "-q"]
    assert main([str(tmp_path / "a" / "first.mcap"), str(tmp_path / "b" / "second.mcap"), *args, "--out",
                 str(out)]) == 0
    cap = capsys.readouterr()
    assert "warning: first: named after its file" in cap.err and "warning: second: named after its file" in cap.err
    assert "the recorded name rest20_g_dps is also" in cap.err
    data = json.loads((out / "results.json").read_text())
    assert [s["name"] for s in data["sequences"]] == ["first", "second"]
    assert [s["recorded_name"] for s in data["sequences"]] == ["rest20_g_dps"] * 2
    assert [r["sequence"] for r in data["results"]] == ["first", "second"]
    # the realistic scenario's random bias stays seeded by the recorded name: the same number alone
    assert main([str(tmp_path / "a" / "first.mcap"), *args, "--out", str(tmp_path / "alone")]) == 0
    alone = json.loads((tmp_path / "alone" / "results.json").read_text())["results"][0]
    assert alone["sequence"] == "rest20_g_dps"
    assert alone["rmse_deg"] == pytest.approx(data["results"][0]["rmse_deg"], abs=1e-9)
