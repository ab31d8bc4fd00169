"""riann-bag-eval under the faults users cause (issue 48): every bad output a clean error before any work, a failure
after the work that keeps every finished result, a changed input evaluated again on --resume, an input given twice
evaluated once, a crafted shard never run, a partial estimate file not ranked, comparisons of unlike runs marked,
reference-free reports without empty sections. Each case: exit status 1 or 2 (or 0 where nothing failed) with one
line naming the cause and the target, no traceback, no finished result lost."""

from __future__ import annotations

import json
import pickle
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from helpers_fs import read_only
from helpers_mag import moving

from conftest import executable
from riann_ros import bagio
from riann_ros.cli.convert import main as convert_main
from riann_ros.cli.evaluate import main
from riann_ros.datasets.synthetic import generate
from riann_ros.evaluation import store

FAST = ["-e", "madgwick", "-s", "as-recorded", "--no-plots", "-q"]
NOTES = FAST[:-1]  # the notes on stderr (a resumed run's count) as well: not --quiet


def line_naming(err: str, *words: str) -> str:
    """The stderr line that names every one of ``words``; no traceback anywhere."""
    assert "Traceback" not in err, err
    lines = [ln for ln in err.splitlines() if all(w in ln for w in words)]
    assert lines, f"no line naming {words}:\n{err}"
    return lines[0]


@pytest.fixture(scope="module")
def bags(tmp_path_factory) -> list[Path]:
    d = tmp_path_factory.mktemp("bags")
    return [bagio.write_recording(d / f"run{k}.mcap", generate(rate=100, duration=20, seed=k, start_s=1.0))
            for k in range(2)]


def rmse(out: Path, estimator: str = "madgwick") -> float:
    rows = json.loads((out / "results.json").read_text())["results"]
    (row,) = [r for r in rows if r["estimator"] == estimator]
    return row["rmse_deg"]


# ---- outputs checked before any work --------------------------------------------------------------------------------
def test_write_estimates_onto_a_file_is_refused_before_any_work(bags, tmp_path, capsys):
    existing = tmp_path / "existing_file.txt"
    existing.write_text("mine")
    out = tmp_path / "o"
    assert main([str(bags[0]), *FAST, "--write-estimates", str(existing), "--out", str(out)]) == 2
    line_naming(capsys.readouterr().err, "--write-estimates", str(existing), "not a folder")
    assert not out.exists() and existing.read_text() == "mine"  # nothing evaluated, nothing kept


def test_out_onto_a_file_is_refused_before_any_work(bags, tmp_path, capsys):
    existing = tmp_path / "o"
    existing.write_text("mine")
    assert main([str(bags[0]), *FAST, "--out", str(existing)]) == 2
    line_naming(capsys.readouterr().err, "--out", str(existing), "not a folder")


@pytest.mark.parametrize("option", ["--out", "--write-estimates"])
def test_an_output_under_a_read_only_folder_is_refused_before_any_work(bags, tmp_path, capsys, option):
    out = tmp_path / "o"
    with read_only(tmp_path / "locked") as locked:
        target = locked / "sub"
        argv = [str(bags[0]), *FAST, option, str(target)] + (["--out", str(out)] if option != "--out" else [])
        assert main(argv) == 2
        line_naming(capsys.readouterr().err, option, str(target), "cannot write into", str(locked))
        assert not target.exists()
    assert not out.exists()


def test_a_write_estimates_clash_is_refused_before_any_work_and_nothing_written(bags, tmp_path, capsys):
    est = tmp_path / "est"
    est.mkdir()
    (est / bags[0].name).write_text("an earlier copy")
    out = tmp_path / "o"
    assert main([str(bags[0]), *FAST, "--write-estimates", str(est), "--out", str(out)]) == 2
    line_naming(capsys.readouterr().err, "--write-estimates", str(est / bags[0].name), "exists", "--force")
    assert [p.name for p in est.iterdir()] == [bags[0].name] and (est / bags[0].name).read_text() == "an earlier copy"
    assert not out.exists()


# ---- a failure after the work keeps every finished result ---------------------------------------------------------
def test_a_clash_found_after_the_run_writes_no_estimate_and_keeps_the_results(tmp_path, capsys):
    """Two recordings named "run a" and "run_a" give one trajectory file name: found only once their names are read,
    so after the run. Nothing is written into the estimates folder; the results are."""
    d = tmp_path / "bags"
    d.mkdir()
    pair = [bagio.write_recording(d / f"{n}.mcap", generate(rate=100, duration=20, seed=k, start_s=1.0, name=name))
            for k, (n, name) in enumerate((("a", "run a"), ("b", "run_a")))]
    est, out = tmp_path / "est", tmp_path / "o"
    assert main([*map(str, pair), *FAST, "--write-estimates", str(est), "--out", str(out)]) == 1
    err = capsys.readouterr().err
    line_naming(err, "--write-estimates", str(est / "run_a.as-recorded.madgwick.tum"), "two inputs")
    line_naming(err, "nothing written in", str(est))
    assert not est.exists() or not list(est.iterdir())
    rows = json.loads((out / "results.json").read_text())["results"]
    assert sorted(r["sequence"] for r in rows) == ["run a", "run_a"]  # every finished result written


def test_write_estimates_with_resume_writes_every_input(bags, tmp_path, capsys):
    whole_est, whole = tmp_path / "est_whole", tmp_path / "whole"
    assert main([*map(str, bags), *FAST, "--write-estimates", str(whole_est), "--out", str(whole)]) == 0
    est, out = tmp_path / "est", tmp_path / "o"
    assert main([*map(str, bags), *FAST, "--write-estimates", str(est), "--out", str(out)]) == 0
    shutil.rmtree(est)  # a run stopped after its first input: no result files, the second shard missing
    for f in ("results.csv", "results.json", "report.md"):
        (out / f).unlink()
    (out / store.SHARDS / store.shard_keys(list(map(str, bags)))[1][1]).unlink()
    capsys.readouterr()
    assert main([*map(str, bags), *NOTES, "--write-estimates", str(est), "--out", str(out), "--resume"]) == 0
    assert "1 of 2 input(s) finished earlier; evaluating 1" in capsys.readouterr().err
    assert sorted(p.name for p in est.iterdir()) == sorted(p.name for p in whole_est.iterdir())
    for f in whole_est.glob("*.tum"):
        assert (est / f.name).read_text() == f.read_text()


# ---- --resume and the inputs ----------------------------------------------------------------------------------------
def test_resume_after_an_input_changed_gives_the_fresh_figure(bags, tmp_path, capsys):
    path = tmp_path / "robot.mcap"
    shutil.copy(bags[0], path)
    out, fresh = tmp_path / "o", tmp_path / "fresh"
    assert main([str(path), *FAST, "--out", str(out)]) == 0
    old = rmse(out)
    shutil.copy(bags[1], path)  # another recording at the same path
    assert main([str(bags[1]), *FAST, "--out", str(fresh)]) == 0
    capsys.readouterr()
    assert main([str(path), *FAST, "--out", str(out), "--resume"]) == 0
    line_naming(capsys.readouterr().err, "warning", str(path), "changed since the earlier run", "evaluated again")
    assert rmse(out) == rmse(fresh) != old


def test_an_input_given_twice_is_evaluated_once(bags, tmp_path, capsys):
    listing = tmp_path / "list.txt"
    listing.write_text(f"{bags[0]}\n{bags[0].parent}/./{bags[0].name}\n")
    out = tmp_path / "o"
    assert main([str(bags[0]), "--inputs-from", str(listing), *FAST, "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert sum("is given more than once" in ln for ln in err.splitlines()) == 2
    line_naming(err, "warning", str(bags[0]), "evaluated once")
    data = json.loads((out / "results.json").read_text())
    assert len(data["results"]) == 1 and data["summary"][0]["n"] == 1


class _Payload:
    """What a crafted pickle runs when loaded: it makes ``marker`` (pathlib's own code, no shell)."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (Path.touch, (self.marker,))


@pytest.mark.parametrize("kind", ["a pickle named as a shard", "an npz holding a pickled object array",
                                  "an old format-1 .pkl shard"])
def test_a_crafted_pickle_shard_is_never_run(bags, tmp_path, capsys, kind):
    out = tmp_path / "o"
    assert main([str(bags[0]), *FAST, "--out", str(out)]) == 0
    live = tmp_path / "proof"
    pickle.loads(pickle.dumps(_Payload(live)))
    assert live.exists()  # the payload does run when unpickled
    marker = tmp_path / "ran"
    shard = out / store.SHARDS / store.shard_keys([str(bags[0])])[0][1]
    payload = pickle.dumps(_Payload(marker))
    if kind == "a pickle named as a shard":
        shard.write_bytes(payload)
    elif kind == "an npz holding a pickled object array":
        with open(shard, "wb") as f:
            np.savez(f, doc=np.array([_Payload(marker)], dtype=object))
    else:
        shard.unlink()
        shard.with_suffix(".pkl").write_bytes(payload)
    capsys.readouterr()
    assert main([str(bags[0]), *NOTES, "--out", str(out), "--resume"]) == 0
    assert "0 of 1 input(s) finished earlier; evaluating 1" in capsys.readouterr().err
    assert not marker.exists()
    assert (out / "results.json").is_file()


# ---- estimate files -------------------------------------------------------------------------------------------------
def test_an_estimate_covering_the_last_tenth_is_not_ranked(bags, tmp_path, capsys):
    est = tmp_path / "est"
    assert main([str(bags[0]), "-e", "vqf", "-s", "as-recorded", "--write-estimates", str(est), "-q",
                 "--no-plots"]) == 0
    (full,) = est.glob("*.vqf.tum")
    lines = [ln for ln in full.read_text().splitlines() if not ln.startswith("#")]
    tail = tmp_path / "tail.tum"
    tail.write_text("\n".join(lines[-len(lines) // 10:]) + "\n")
    out = tmp_path / "o"
    capsys.readouterr()
    assert main([str(bags[0]), "-e", "vqf", "--estimate-file", f"{tail}:mine", "-s", "as-recorded", "--out",
                 str(out), "-q"]) == 0
    captured = capsys.readouterr()
    line_naming(captured.err, "warning", "the estimate mine covers", "of the scored span", "not ranked")
    assert "estimate mine: covers" in captured.out
    data = json.loads((out / "results.json").read_text())
    assert [g["estimator"] for g in data["summary"]] == ["vqf"]  # mine is not ranked
    (mine,) = [r for r in data["results"] if r["estimator"] == "mine"]
    assert 0 < mine["coverage"] == mine["n_scored"] / (mine["n_scored"] + mine["n_unestimated"]) < 0.1
    assert "not ranked" in (out / "report.md").read_text()


def test_a_huge_quaternion_in_an_estimate_file_is_one_line_without_a_numpy_warning(bags, tmp_path):
    f = tmp_path / "big.tum"
    f.write_text("1.0 0 0 0 0 0 0 1\n2.0 0 0 0 1e300 0 0 1e300\n")
    r = subprocess.run([str(executable("riann-bag-eval")), str(bags[0]), "--estimate-file", f"{f}:big", "-e", "vqf",
                        "-s", "as-recorded", "-q"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2
    assert r.stderr.strip().count("\n") == 0, r.stderr  # one line
    line_naming(r.stderr, str(f), "estimate quaternion norm", "not ≈ 1")
    assert "Warning" not in r.stderr and "reference" not in r.stderr


def test_estimate_file_messages_say_estimate(bags, tmp_path, capsys):
    f = tmp_path / "est.csv"
    f.write_text("time[s],w,x,y,z\n1.0,1,0,0,0\n")
    assert main([str(bags[0]), "--estimate-file", f"{f}:e", *FAST]) == 2
    err = capsys.readouterr().err
    line_naming(err, str(f), "no estimate column")
    assert "ground-truth" not in err and "reference quaternion" not in err


# ---- reports that must not mislead ----------------------------------------------------------------------------------
def test_compare_of_a_9d_and_a_6d_run_with_other_seeds_says_so(tmp_path, capsys):
    bag = bagio.write_recording(tmp_path / "mag.mcap", moving(duration=20.0))
    a, b = tmp_path / "nine", tmp_path / "six"
    assert main([str(bag), *FAST, "--out", str(a)]) == 0
    assert main([str(bag), *FAST, "--use-mag", "false", "--seed", "3", "--out", str(b)]) == 0
    capsys.readouterr()
    assert main(["--compare", str(a), str(b)]) == 0
    text = capsys.readouterr().out
    assert "A and B differ in sensors" in text
    assert any(ln.startswith("NOTE: the sensors differ") and "9D" in ln and "6D" in ln for ln in text.splitlines())
    assert any(ln.startswith("NOTE: A and B were run with other settings") and "seed: A 0, B 3" in ln
               for ln in text.splitlines())


def test_a_reference_free_report_holds_only_sections_with_content(tmp_path, capsys):
    rec = generate(rate=100, duration=20, seed=5, start_s=1.0)
    rec.quat_ref = None
    bag = bagio.write_recording(tmp_path / "robot.mcap", rec)
    out = tmp_path / "o"
    assert main([str(bag), "-e", "madgwick,vqf", "--out", str(out), "-q"]) == 0  # all scenarios asked for
    md = (out / "report.md").read_text()
    assert "## Summary" not in md and "## Per sequence" not in md and "Metric:" not in md
    assert "Scenarios: as-recorded;" in md  # the one that ran
    assert "## Without a reference" in md


def test_the_converter_says_no_reference(tmp_path, capsys):
    rec = generate(motion="combined", rate=100.0, duration=20.0, seed=4)
    csv = tmp_path / "robot.csv"
    np.savetxt(csv, np.column_stack([rec.t, rec.acc, rec.gyr]), delimiter=",",
               header="t,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z", comments="", fmt="%.9f")
    assert convert_main([str(csv), "-o", str(tmp_path / "robot.mcap")]) == 0
    line = line_naming(capsys.readouterr().err, str(csv), "no reference")
    assert "0 reference" not in line and "scored" not in line


def test_a_missing_broad_file_says_where_to_get_broad(tmp_path, capsys):
    missing = tmp_path / "shared" / "datasets" / "broad" / "07_undisturbed_fast_rotation_B.hdf5"
    assert main([str(missing), *FAST]) == 1
    line_naming(capsys.readouterr().err, str(missing), "no such file", "https://doi.org/10.3390/data6070072")
    assert convert_main([str(missing), "-o", str(tmp_path / "t.mcap")]) == 1
    line_naming(capsys.readouterr().err, str(missing), "https://doi.org/10.3390/data6070072")
    assert not (tmp_path / "t.mcap").exists()
