"""A run's results kept as they come (riann_ros.evaluation.store, riann_ros.evaluation.fleet): every finished input in
OUT/shards at once; --resume evaluates only what is missing and writes the same files as an uninterrupted run; other
settings are refused naming each difference; a folder holding kept inputs is never mixed with a new run; a shard is
there whole or not at all."""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import pytest
from test_evaluation import synthetic

from riann_ros.cli.evaluate import main
from riann_ros.evaluation import store
from riann_ros.evaluation.fleet import _Kept
from riann_ros.evaluation.results import EvalSettings, SequenceResult
from riann_ros.evaluation.specs import parse_estimators

bagio = pytest.importorskip("riann_ros.bagio")
TIMING = {"seconds", "cpu_seconds"}


@pytest.fixture(scope="module")
def bags(tmp_path_factory) -> list[str]:
    d = tmp_path_factory.mktemp("bags")
    return [str(bagio.write_recording(d / f"s{k}.mcap", synthetic(name=f"s{k}", t0_ns=1_700_000_000_000_000_000,
                                                                    gyr_bias=(0.01 * k, -0.02, 0.005))))
            for k in range(3)]


def args(bags: list[str], out: Path, *more: str) -> list[str]:
    return [*bags, "-e", "madgwick,vqf", "-s", "realistic", "-p", "none", "-p", "bias:3,3,0", "--out", str(out),
            *more]


def results(out: Path) -> dict:
    """results.json without what differs between two runs of the same settings (times, the command)."""
    data = json.loads((out / "results.json").read_text())
    for row in data["results"]:
        for k in TIMING:
            row.pop(k)
    for seq in data["sequences"]:
        for k in TIMING:
            seq.pop(k)
    for k in ("elapsed_s", "versions"):
        data.pop(k)
    data["settings"].pop("command")
    return data


def report_text(out: Path) -> str:
    text = (out / "report.md").read_text()
    return re.sub(r"Command: `[^`]*`", "", text)


def files(out: Path) -> list[str]:
    return sorted(p.name for p in out.iterdir() if p.is_file())


@pytest.fixture(scope="module")
def uninterrupted(bags, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("whole") / "out"
    assert main(args(bags, out, "-q")) == 0
    return out


def _stopped_run(bags: list[str], out: Path, lose: list[int]) -> None:
    """A run as a kill leaves it: no result files, and the shards of the inputs in ``lose`` not written."""
    assert main(args(bags, out, "-q")) == 0
    for f in ("results.csv", "results.json", "report.md", *[p.name for p in out.glob("*.png")],
              *[p.name for p in out.glob("*.svg")]):
        (out / f).unlink()
    keys = store.shard_keys(bags)
    for i in lose:
        (out / store.SHARDS / keys[i][1]).unlink()


@pytest.mark.slow
def test_every_finished_input_is_kept_at_once(bags, uninterrupted):
    shards = sorted(p.name for p in (uninterrupted / store.SHARDS).glob(f"*{store.SUFFIX}"))
    assert shards == sorted(name for _, name in store.shard_keys(bags))
    assert json.loads((uninterrupted / store.SHARDS / store.MANIFEST).read_text())["format"] == store.FORMAT


@pytest.mark.slow
@pytest.mark.parametrize("lose", [[0], [1, 2]], ids=["the plotted first input", "the last two"])
def test_resume_evaluates_only_what_is_missing_and_writes_the_same_files(bags, uninterrupted, tmp_path, capsys, lose):
    out = tmp_path / "out"
    _stopped_run(bags, out, lose)
    capsys.readouterr()
    assert main(args(bags, out, "--resume")) == 0
    err = capsys.readouterr().err
    assert f"{3 - len(lose)} of 3 input(s) finished earlier; evaluating {len(lose)}" in err
    assert f"{len(lose)}/{len(lose)}" in err  # the progress bar counts this run's inputs
    assert results(out) == results(uninterrupted)
    assert report_text(out) == report_text(uninterrupted)
    assert files(out) == files(uninterrupted)  # the same plots


@pytest.mark.slow
def test_resume_with_other_settings_is_refused_naming_what_differs(bags, uninterrupted, tmp_path, capsys):
    out = tmp_path / "out"
    _stopped_run(bags, out, [2])
    capsys.readouterr()
    other = [*bags, "-e", "madgwick", "-s", "realistic", "-p", "none", "-p", "bias:3,3,0", "--seed", "3",
             "--out", str(out), "--resume"]
    assert main(other) == 2
    err = capsys.readouterr().err
    assert "cannot resume" in err
    assert "seed (--seed): 0 in the earlier run, 3 now" in err
    assert re.search(r"estimators \(--estimators\): \[.*vqf.*\] in the earlier run, \[.*madgwick.*\] now", err)
    assert not (out / "results.csv").exists() and len(list((out / store.SHARDS).glob(f"*{store.SUFFIX}"))) == 2


@pytest.mark.slow
def test_a_new_run_into_kept_inputs_is_refused_and_force_starts_over(bags, tmp_path, capsys):
    out = tmp_path / "out"
    _stopped_run(bags, out, [2])
    capsys.readouterr()
    assert main(args(bags, out, "-q")) == 2  # the same command again: it would mix or lose that run
    err = capsys.readouterr().err
    assert "holds an earlier run's results of 2 input(s)" in err and "--resume" in err and "--force" in err
    assert main(args(bags, out, "-q", "--force", "-e", "vqf")) == 0  # -e given twice: the last one counts
    assert {r["estimator"] for r in json.loads((out / "results.json").read_text())["results"]} == {"vqf"}
    assert len(list((out / store.SHARDS).glob(f"*{store.SUFFIX}"))) == 3


def test_resume_needs_out_and_does_not_combine_with_force(tmp_path, capsys):
    bags = ["a.mcap"]  # refused before any input is read
    assert main([bags[0], "--resume", "-q"]) == 2
    assert "give --out" in capsys.readouterr().err
    assert main(args(bags, tmp_path / "o", "--resume", "--force")) == 2
    assert "does not combine with --force" in capsys.readouterr().err


@pytest.mark.slow
def test_resume_of_nothing_is_a_fresh_run_and_of_a_finished_run_rewrites_its_files(bags, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(args(bags, out, "-q", "--resume")) == 0
    first = results(out)
    capsys.readouterr()
    assert main(args(bags, out, "--resume")) == 0
    assert "3 of 3 input(s) finished earlier; evaluating 0" in capsys.readouterr().err
    assert results(out) == first


@pytest.mark.slow
def test_a_damaged_or_half_written_shard_counts_as_not_finished(bags, tmp_path, capsys):
    out = tmp_path / "out"
    _stopped_run(bags, out, [])
    keys = store.shard_keys(bags)
    shard = out / store.SHARDS / keys[1][1]
    shard.write_bytes(shard.read_bytes()[:100])  # what a disk error leaves (a kill leaves a temporary file)
    (out / store.SHARDS / f".{keys[2][1]}.123.tmp").write_bytes(b"half")
    capsys.readouterr()
    assert main(args(bags, out, "--resume")) == 0
    assert "2 of 3 input(s) finished earlier; evaluating 1" in capsys.readouterr().err
    assert not list((out / store.SHARDS).glob(".*.tmp"))


def test_fingerprint_and_differences():
    a = store.fingerprint(EvalSettings(parse_estimators("madgwick")), ("mahony:kp=1/2",), "realistic")
    b = store.fingerprint(EvalSettings(parse_estimators("madgwick"), seed=1))
    assert json.loads(json.dumps(a)) == a  # as run.json holds it
    diff = store.differences(a, b)
    assert "seed: 0 in the earlier run, 1 now" in diff
    assert 'tune: ["mahony:kp=1/2"] in the earlier run, null now' in diff
    assert store.differences(a, a) == []


def test_an_input_given_twice_has_two_shards():
    keys = store.shard_keys(["a.mcap", "b.mcap", "a.mcap"])
    assert [k for k, _ in keys] == [0, 0, 1] and len({n for _, n in keys}) == 3


def test_only_the_plotted_series_are_kept_whatever_the_order_inputs_finish(tmp_path):
    sources = ["a", "b", "c"]
    shards = store.ShardStore(tmp_path, store.fingerprint(EvalSettings([])), store.NEW, sources)
    kept = _Kept(3, "*", shards)
    series = {"sequence": "x", "conditions": {}}
    for i in (2, 1, 0):  # the last input first, as a cluster may finish them
        kept.add(i, SequenceResult(source=sources[i], name=sources[i], series=dict(series)))
        held = [r.series is not None for r in kept.results if r is not None]
        assert held.count(True) == 1  # one series in memory at any time
    assert [r.series is not None for r in kept.results if r is not None] == [True, False, False]
    on_disk = shards.load()
    assert [on_disk[i].series is not None for i in range(3)] == [True, False, False]
    every = _Kept(3, "all", None)  # --plot-sequence all: every sequence is plotted
    for i in (2, 0):
        every.add(i, SequenceResult(source=sources[i], series=dict(series)))
    assert [r is not None and r.series is not None for r in every.results] == [True, False, True]


# ---- the shards are data, read back with validation ----------------------------------------------------------------
def _same(a, b, where="result") -> None:
    """``a`` and ``b`` hold the same values (dataclasses by field, arrays by value and dtype, NaN equal to NaN)."""
    import dataclasses

    import numpy as np

    if dataclasses.is_dataclass(a):
        assert type(a) is type(b), where
        for f in dataclasses.fields(a):
            _same(getattr(a, f.name), getattr(b, f.name), f"{where}.{f.name}")
    elif isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray) and a.dtype == b.dtype and a.shape == b.shape, where
        assert np.array_equal(a, b, equal_nan=a.dtype.kind in "fc"), where
    elif isinstance(a, dict):
        assert isinstance(b, dict) and list(a) == list(b), where
        for k in a:
            _same(a[k], b[k], f"{where}[{k!r}]")
    elif isinstance(a, list | tuple):
        assert type(a) is type(b) and len(a) == len(b), where
        for k, (x, y) in enumerate(zip(a, b, strict=True)):
            _same(x, y, f"{where}[{k}]")
    elif isinstance(a, float) and a != a:
        assert b != b, where
    else:
        assert a == b and type(a) is type(b), (where, a, b)


@pytest.fixture(scope="module")
def rich_results(bags, tmp_path_factory) -> list[SequenceResult]:
    """Results with everything a shard holds: plot series, kept estimates, two conditions, σ histograms; and a
    reference-free input (agreement, attitude series, health)."""
    from riann_ros.datasets.synthetic import generate
    from riann_ros.evaluation.perturb import parse_condition
    from riann_ros.evaluation.run import evaluate_source

    rec = generate(rate=100, duration=20, seed=5, start_s=1.0)
    rec.quat_ref = None
    free = bagio.write_recording(tmp_path_factory.mktemp("free") / "free.mcap", rec)
    s = EvalSettings(parse_estimators("madgwick,vqf"), scenarios=["as-recorded", "realistic"], series_for="*",
                     keep_estimates=True, conditions=[parse_condition("none"), parse_condition("bias:3,3,0")])
    out = [evaluate_source(src, s) for src in (bags[0], str(free))]
    assert not any(r.error for r in out) and out[0].series and out[0].estimates and out[1].agreement
    return out


def test_a_shard_gives_back_every_value_of_the_result(rich_results, tmp_path):
    shards = store.ShardStore(tmp_path, store.fingerprint(EvalSettings([])), store.NEW,
                              [r.source for r in rich_results])
    for i, res in enumerate(rich_results):
        shards.write(i, res)
    back = shards.load()
    for i, res in enumerate(rich_results):
        _same(res, back[i])
    assert not list(tmp_path.rglob("*.pkl"))


@pytest.mark.parametrize("change, why", [
    (lambda doc: doc["value"]["f"].update(name=3), "SequenceResult.name is not a str"),
    (lambda doc: doc["value"].update({"$dc": "Popen"}), "unknown record 'Popen'"),
    (lambda doc: doc["value"]["f"].update(shell="rm -rf /"), "no field 'shell'"),
    (lambda doc: doc["value"]["f"]["rows"][0]["f"]["score"]["f"].update(n_scored=1.5), "Score.n_scored"),
    (lambda doc: doc["value"]["f"].update(series={"$arr": "a999"}), "no array 'a999'"),
])
def test_a_shard_that_breaks_the_record_types_is_refused_naming_why(rich_results, tmp_path, change, why):
    from riann_ros.evaluation import shard_codec

    data = shard_codec.encode({"format": store.FORMAT}, rich_results[0])
    import io

    import numpy as np

    arrays = dict(np.load(io.BytesIO(data)))
    doc = json.loads(arrays["doc"].tobytes())
    change(doc)
    arrays["doc"] = np.frombuffer(json.dumps(doc).encode(), dtype=np.uint8)
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    with pytest.raises(shard_codec.ShardError, match=re.escape(why)):
        shard_codec.decode(buf.getvalue(), "crafted.npz")


def test_a_shard_holds_only_the_evaluators_records():
    from riann_ros.evaluation import shard_codec

    with pytest.raises(TypeError, match="cannot hold"):
        shard_codec.encode({}, SequenceResult(source="a", health={"x": object()}))


def test_the_tuning_is_kept_as_data(tmp_path):
    from riann_ros.evaluation.specs import EstimatorSpec

    shards = store.ShardStore(tmp_path, store.fingerprint(EvalSettings([])), store.NEW, ["a"])
    tuned = [({"estimator": "mahony", "best": {"label": "mahony(kp=1)", "mean": 1.5, "params": {"kp": 1.0}}},
              EstimatorSpec.of("mahony", {"kp": 1.0}, "mahony(kp=1) tuned"))]
    shards.save_tuning(tuned)
    assert shards.tuning() == tuned
    (tmp_path / store.SHARDS / store.TUNING).write_bytes(b"\x80\x04garbage")
    assert shards.tuning() is None  # not readable as a tuning: tuned again


def test_an_input_changed_since_its_shard_is_named_and_not_loaded(bags, tmp_path):
    import shutil

    path = tmp_path / "robot.mcap"
    shutil.copy(bags[0], path)
    shards = store.ShardStore(tmp_path / "o", store.fingerprint(EvalSettings([])), store.NEW, [str(path)])
    shards.write(0, SequenceResult(source=str(path), name="robot"))
    assert store.stale(tmp_path / "o", [str(path)]) == [] and 0 in shards.load()
    shutil.copy(bags[1], path)
    ((src, why),) = store.stale(tmp_path / "o", [str(path)])
    assert src == str(path) and "other content" in why
    assert shards.load() == {} and "other content" in shards.changed[0]
    os.utime(path, ns=(0, 0))  # the same bytes, touched: modified since
    assert "modified since" in store.changed(store.identity(bags[1]), store.identity(path))
    assert store.changed(store.identity(path), store.identity(path)) == ""
