"""The result pages cannot go stale: every marked table and figure in README.md, docs/results.md and BENCHMARKS.md
is what bench/results_tables.py writes from the committed docs/results/*.json."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pytest
import results_tables as rt

from conftest import ROOT


def test_committed_pages_match_the_committed_results():
    assert rt.stale() == [], "run .venv/bin/python bench/results_tables.py and commit the pages"


def test_every_block_is_known_and_every_table_is_shown():
    shown = {m["name"] for p in rt.PAGES for m in rt.MARKER.finditer((ROOT / p).read_text())}
    assert shown == set(rt.TABLES)


def test_a_changed_figure_is_caught(tmp_path: Path):
    for p in rt.PAGES:
        (tmp_path / p).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(ROOT / p, tmp_path / p)
    page = tmp_path / "docs" / "results.md"
    text = page.read_text()
    m = next(rt.MARKER.finditer(text))
    body = m["body"]
    i = next(k for k, ch in enumerate(body) if ch.isdigit())
    changed = body[:i] + str((int(body[i]) + 1) % 10) + body[i + 1:]
    page.write_text(text[:m.start("body")] + changed + text[m.end("body"):])
    assert rt.stale(tmp_path) == ["docs/results.md"]


def test_trim_keeps_only_the_table_fields(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    row = {"sequence": "01_x", "dataset": "broad", "source": "/somewhere/01_x.mat", "scenario": "as-recorded",
           "perturbation": "none", "rate": "native", "estimator": "riann", "sensors": "6D", "rmse_deg": 0.123456789,
           "max_err_deg": 2.0, "n_samples": 10}
    rows = [row, {**row, "estimator": "vqf"}, {**row, "scenario": "realistic", "rmse_deg": 0.5}]
    (tmp_path / "results.json").write_text(json.dumps({"results": rows}))
    monkeypatch.setattr(rt, "RESULTS", tmp_path)
    rt.trim("x", [tmp_path / "results.json"], "riann-bag-eval x")
    data = json.loads((tmp_path / "x.json").read_text())
    assert data["command"] == "riann-bag-eval x" and "source" not in data["columns"]
    assert data["same"] == {"perturbation": "none", "rate": "native", "sequence": "01_x", "sensors": "6D"}
    got = rt.load("x")
    assert got.where(estimator="vqf").values("vqf") == [0.123457]
    assert got.where(scenario="as-recorded").mean_max("riann") == "0.12 / 0.12"
    assert got.mean_max("riann") == "0.31 / 0.50"


def test_no_absolute_paths_in_the_committed_results():
    for f in sorted((ROOT / "docs" / "results").glob("*.json")):
        assert '"/' not in f.read_text() and " /" not in f.read_text(), f.name


def test_the_evo_example_check_catches_a_changed_figure_not_the_wall_time():
    import evo_example

    committed = json.loads(evo_example.RESULT.read_text())
    assert evo_example.differences(committed, committed) == []
    timed = json.loads(json.dumps(committed))
    timed["outputs"][0] = re.sub(r"evaluated in [\d.]+ s", "evaluated in 99.9 s", timed["outputs"][0])
    assert evo_example.differences(committed, timed) == []
    moved = json.loads(json.dumps(committed))
    moved["outputs"][1] = moved["outputs"][1].replace("rmse\t", "rmse\t9", 1)
    moved["rows"]["eval21/riann"]["total_rmse_deg"] += 0.01
    before, after = (r["rows"]["eval21/riann"]["total_rmse_deg"] for r in (committed, moved))
    assert evo_example.differences(committed, moved) == [
        f"the output of {evo_example.COMMANDS[1]}", f"eval21/riann total_rmse_deg: {before} committed, {after} now"]


@pytest.mark.slow
def test_the_evo_example_commands_give_the_committed_figures():
    """docs/evaluation.md's evo blocks are written from docs/results/evo.json; its commands, run now, give it."""
    import evo_example

    assert evo_example.main(["--check"]) == 0
