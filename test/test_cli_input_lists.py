"""``riann-bag-eval --inputs-from FILE`` (riann_ros.cli.input_lists): one path or glob a line, comments and blank lines
skipped, relative paths from the list's folder, globs sorted; a glob that matches nothing refused before any work."""

from __future__ import annotations

import io
import json
import sys
from pathlib import Path

import pytest

from conftest import ROOT
from riann_ros.cli.evaluate import main
from riann_ros.cli.input_lists import inputs_from


def test_paths_globs_comments_and_blank_lines(tmp_path):
    corpus = tmp_path / "corpus"
    (corpus / "2026" / "robot2").mkdir(parents=True)
    for name in ("b.mcap", "a.mcap", "2026/robot2/c.mcap", "2026/robot2/notes.txt"):
        (corpus / name).write_text("")
    listing = corpus / "list.txt"
    listing.write_text("# the fleet's recordings\n\n  b.mcap  \n*.mcap\n**/*.mcap\n/abs/elsewhere.mcap\n"
                       "missing.mcap\n   # indented comment\n")
    got = inputs_from([str(listing)])
    assert got == [str(corpus / "b.mcap"), str(corpus / "a.mcap"), str(corpus / "b.mcap"),
                   str(corpus / "2026/robot2/c.mcap"), str(corpus / "a.mcap"), str(corpus / "b.mcap"),
                   "/abs/elsewhere.mcap", str(corpus / "missing.mcap")]


def test_relative_paths_start_from_the_lists_folder(tmp_path, monkeypatch):
    (tmp_path / "lists").mkdir()
    (tmp_path / "lists" / "l.txt").write_text("../bags/x.mcap\n")
    monkeypatch.chdir(tmp_path)
    assert inputs_from(["lists/l.txt"]) == ["bags/x.mcap"]


def test_standard_input(monkeypatch):
    monkeypatch.setattr(sys, "stdin", io.StringIO("bags/a.mcap\n# no\nbags/b.mcap\n"))
    assert inputs_from(["-"]) == ["bags/a.mcap", "bags/b.mcap"]


def test_a_glob_without_match_or_an_unreadable_list_is_refused_before_any_work(tmp_path, capsys):
    listing = tmp_path / "l.txt"
    listing.write_text("# fine\nnothing_here/*.mcap\n")
    assert main(["--inputs-from", str(listing), "-e", "madgwick"]) == 2
    assert "l.txt, line 2: 'nothing_here/*.mcap' matches no file" in capsys.readouterr().err
    assert main(["--inputs-from", str(tmp_path / "absent.txt")]) == 2
    assert "cannot read it" in capsys.readouterr().err


def test_inputs_from_an_empty_list_is_no_input(tmp_path, capsys):
    listing = tmp_path / "l.txt"
    listing.write_text("# nothing yet\n")
    with pytest.raises(SystemExit) as exc:
        main(["--inputs-from", str(listing)])
    assert exc.value.code == 2 and "no input given" in capsys.readouterr().err


@pytest.mark.slow
def test_the_listed_inputs_follow_the_command_lines_in_order(tmp_path):
    bags = ROOT / "bags"
    listing = tmp_path / "l.txt"
    listing.write_text(f"{bags / 'synthetic_translation_200hz.mcap'}\n{bags}/synthetic_c*.mcap\n")
    out = tmp_path / "out"
    assert main([str(bags / "synthetic_rotation_100hz.mcap"), "--inputs-from", str(listing), "-e", "madgwick",
                 "-s", "realistic", "--no-plots", "-q", "--out", str(out)]) == 0
    seqs = [s["name"] for s in json.loads((out / "results.json").read_text())["sequences"]]
    assert seqs == ["synthetic_rotation_seed2_100hz", "synthetic_translation_seed3_200hz",
                    "synthetic_combined_seed1_200hz"]
    assert Path(json.loads((out / "results.json").read_text())["settings"]["inputs"][2]).name == (
        "synthetic_combined_200hz.mcap")


def test_an_input_given_twice_is_kept_once_by_its_resolved_path(tmp_path, monkeypatch):
    from riann_ros.cli.input_lists import deduplicated

    (tmp_path / "a.mcap").write_text("")
    (tmp_path / "b.mcap").write_text("")
    (tmp_path / "link.mcap").symlink_to(tmp_path / "a.mcap")
    (tmp_path / "hard.mcap").hardlink_to(tmp_path / "b.mcap")
    monkeypatch.chdir(tmp_path)
    kept, warnings = deduplicated(["a.mcap", "b.mcap", "./a.mcap", str(tmp_path / "link.mcap"), "a.mcap",
                                   "hard.mcap"])
    assert kept == ["a.mcap", "b.mcap", "hard.mcap"]  # a hard link is a file of its own path
    assert warnings == ["./a.mcap is given more than once (as a.mcap): evaluated once",
                        f"{tmp_path / 'link.mcap'} is given more than once (as a.mcap): evaluated once",
                        "a.mcap is given more than once: evaluated once"]
