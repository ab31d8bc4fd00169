"""Where riann-bag-eval's unit of work runs (riann_ros.evaluation.executors): on a real Dask cluster — a scheduler
and two workers started with the venv's ``dask scheduler`` / ``dask worker`` over TCP on localhost — the results
equal ``--jobs 2``'s row by row, in 9D, with the inputs in reverse order; a worker killed mid-run loses only its
input, which runs again on the other; an input the workers cannot see fails at once, naming the worker; ``local:N``;
without Dask, ``--scheduler`` says how to install it."""

from __future__ import annotations

import csv
import math
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import ROOT, executable, wait_for
from riann_ros import bagio
from riann_ros.cli.evaluate import main
from riann_ros.datasets.broad import broad_files
from riann_ros.datasets.synthetic import generate
from riann_ros.evaluation import executors

pytest.importorskip("distributed")
from helpers_dask import DaskProcesses, start_cluster

TIMING = {"seconds", "cpu_seconds"}  # the only columns that differ between two runs of the same settings


def evaluate(args: list[str], cwd: Path = ROOT, timeout: float = 900) -> subprocess.CompletedProcess:
    return subprocess.run([str(executable("riann-bag-eval")), *args], capture_output=True, text=True, cwd=cwd,
                          timeout=timeout, env=os.environ.copy())


def rows(out: Path) -> list[dict[str, str]]:
    with open(out / "results.csv") as f:
        return list(csv.DictReader(f))


def assert_same_rows(a: list[dict[str, str]], b: list[dict[str, str]], tol: float = 1e-9) -> None:
    """The same rows in the same order; every number within ``tol`` (the RMSE and every other score)."""
    assert len(a) == len(b) and a, (len(a), len(b))
    for ra, rb in zip(a, b, strict=True):
        assert ra.keys() == rb.keys()
        for k in ra.keys() - TIMING:
            if ra[k] == rb[k]:
                continue
            x, y = float(ra[k]), float(rb[k])  # a text column that differs fails here
            assert math.isclose(x, y, rel_tol=0, abs_tol=tol), (k, ra["sequence"], ra["estimator"], x, y)


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    """A scheduler and two workers, started in a folder of their own (not the repository)."""
    d = tmp_path_factory.mktemp("dask")
    c = start_cluster(d, d)
    yield c
    c.close()


@pytest.fixture(scope="module")
def long_bags(tmp_path_factory) -> list[Path]:
    """Three synthetic bags long enough (60 s at 1 kHz) that a run can be stopped while a worker holds one."""
    d = tmp_path_factory.mktemp("long")
    return [bagio.write_recording(d / f"syn{k}.mcap", generate(rate=1000, duration=60, seed=k, start_s=1.0))
            for k in range(3)]


LONG_ARGS = ["-e", "riann", "-s", "realistic", "--no-plots", "-q"]


@pytest.fixture(scope="module")
def long_reference(long_bags, tmp_path_factory) -> list[dict[str, str]]:
    out = tmp_path_factory.mktemp("ref") / "jobs2"
    r = evaluate([*map(str, long_bags), *LONG_ARGS, "--jobs", "2", "--out", str(out)])
    assert r.returncode == 0, r.stderr
    return rows(out)


@pytest.mark.slow
@pytest.mark.broad
def test_cluster_equals_jobs_2_on_broad_with_two_perturbations(broad_dir, cluster, tmp_path):
    # every second trial (slow, fast, disturbed; .mat and .hdf5) in 9D; the cluster gets them in reverse order, so
    # each worker evaluates the inputs after other inputs than under --jobs 2: no input's rows may depend on that
    trials = [str(p) for p in broad_files(broad_dir)][::2]
    common = ["-e", "madgwick,vqf", "-s", "as-recorded", "-p", "jitter:10/20/30ms", "-p", "bias:3,3,0",
              "--no-plots", "-q"]
    ref = evaluate([*trials, *common, "--jobs", "2", "--out", str(tmp_path / "jobs2")])
    assert ref.returncode == 0, ref.stderr
    got = evaluate([*trials[::-1], *common, "--scheduler", cluster.address, "--out", str(tmp_path / "cluster")])
    assert got.returncode == 0, got.stderr
    got_rows, stems = rows(tmp_path / "cluster"), [Path(t).stem for t in trials]
    assert len(got_rows) == len(trials) * 2 * 2  # trials × estimators × conditions
    assert [r["sequence"] for r in got_rows[::4]] == stems[::-1]  # in input order
    assert_same_rows(rows(tmp_path / "jobs2"), sorted(got_rows, key=lambda r: stems.index(r["sequence"])))
    assert all(r["heading_rmse_deg"] and r["n_yaw_mag"] != "" for r in got_rows)  # 9D: a heading scored
    assert f"{len(trials)} of {len(trials)} input(s) evaluated" in got.stdout


def _worker_holding_an_input(cluster: DaskProcesses) -> str | None:
    """The name of a worker that is evaluating one of the run's inputs right now (None: none is)."""
    with cluster.client() as c:
        names = {addr: w["name"] for addr, w in c.scheduler_info()["workers"].items()}
        for addr, keys in c.processing().items():
            if any(str(k).startswith("riann-eval-") for k in keys):
                return str(names[addr])
    return None


@pytest.mark.slow
def test_a_worker_killed_mid_run_loses_only_its_input_which_runs_again(long_bags, long_reference, tmp_path):
    cluster = start_cluster(tmp_path, tmp_path)
    try:
        out = tmp_path / "out"
        err = tmp_path / "stderr.txt"
        cmd = [str(executable("riann-bag-eval")), *map(str, long_bags), *LONG_ARGS, "--scheduler", cluster.address,
               "--out", str(out)]
        p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=err.open("w"), text=True, env=os.environ.copy())
        held: dict[str, str | None] = {"worker": None}

        def holding() -> bool:
            if p.poll() is not None:
                return True
            held["worker"] = _worker_holding_an_input(cluster)
            return held["worker"] is not None

        wait_for(holding, 300, "a worker evaluating an input", period=0.2)
        assert p.poll() is None and held["worker"], "the run finished before a worker could be killed"
        cluster.kill(held["worker"])  # the machine is gone, with the input it was evaluating
        stdout, _ = p.communicate(timeout=600)
        assert p.returncode == 0, err.read_text()
        assert f"{len(long_bags)} of {len(long_bags)} input(s) evaluated" in stdout
        assert "FAILED" not in err.read_text()
        assert_same_rows(long_reference, rows(out))
        assert "Remove worker" in cluster.log("scheduler")  # the scheduler saw it die and moved its task
    finally:
        cluster.close()


@pytest.mark.slow
def test_client_killed_mid_run_then_resume_completes_the_same_results(cluster, long_bags, long_reference, tmp_path):
    out = tmp_path / "out"
    args = [*map(str, long_bags), *LONG_ARGS, "--scheduler", cluster.address, "--out", str(out)]
    p = subprocess.Popen([str(executable("riann-bag-eval")), *args], stdout=subprocess.DEVNULL,
                         stderr=subprocess.DEVNULL, start_new_session=True, env=os.environ.copy())
    try:
        wait_for(lambda: p.poll() is not None or any((out / "shards").glob("*.npz")), 300, "the first input kept",
                 period=0.05)
        assert p.poll() is None, "the run finished before it could be killed"
        os.killpg(p.pid, signal.SIGKILL)  # no clean-up of any kind
        p.wait(30)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
    kept = len(list((out / "shards").glob("*.npz")))
    assert 1 <= kept < len(long_bags) and not (out / "results.csv").exists()
    r = evaluate([*(a for a in args if a != "-q"), "--resume"])  # the note on what is resumed
    assert r.returncode == 0, r.stderr
    assert f"{kept} of {len(long_bags)} input(s) finished earlier; evaluating {len(long_bags) - kept}" in r.stderr
    assert_same_rows(long_reference, rows(out))


@pytest.mark.slow
def test_an_input_the_workers_cannot_see_fails_at_once_naming_the_worker(cluster, tmp_path):
    # the workers were started in another folder: a relative path that this shell sees is not there for them
    # (the other input another bag: this shell sees one file at both paths, and gives a file once)
    seen = str(ROOT / "bags" / "synthetic_translation_200hz.mcap")
    r = evaluate(["bags/synthetic_rotation_100hz.mcap", seen, "-e", "madgwick", "-s", "as-recorded", "-q",
                  "--scheduler", cluster.address], timeout=300)
    assert r.returncode == 1, r.stdout + r.stderr
    line = next(ln for ln in r.stderr.splitlines() if "FAILED" in ln)
    assert line.startswith("riann-bag-eval: FAILED bags/synthetic_rotation_100hz.mcap: not found on the Dask worker")
    assert os.path.realpath(cluster.logs) in line  # the worker's folder, where a relative path is looked for
    assert "1 of 2 input(s) evaluated" in r.stdout


@pytest.mark.slow
def test_local_cluster_equals_in_process(tmp_path):
    # in-process equals --jobs 2: test_cli_evaluate.py::test_same_seed_same_numbers_parallel_or_not
    bags = sorted(str(p) for p in (ROOT / "bags").glob("synthetic_*.mcap"))
    common = [*bags, "-e", "madgwick,vqf", "-s", "realistic", "-p", "none", "-p", "bias:3,3,0",
              "--no-plots", "-q"]
    for name, extra in (("one", []), ("local2", ["--scheduler", "local:2"])):
        r = evaluate([*common, *extra, "--out", str(tmp_path / name)])
        assert r.returncode == 0, r.stderr
    assert_same_rows(rows(tmp_path / "one"), rows(tmp_path / "local2"))


def test_scheduler_without_dask_says_how_to_install(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "distributed", None)  # what an install without the cluster extra has
    bag = str(ROOT / "bags" / "synthetic_rotation_100hz.mcap")
    assert main([bag, "-e", "madgwick", "--scheduler", "local:2", "-q"]) == 2
    err = capsys.readouterr().err
    assert "pip install 'riann_ros[cluster]'" in err and "requirements-cluster.txt" in err


@pytest.mark.parametrize("text, why", [("local:0", "N >= 1"), ("local:x", "N >= 1"), ("myhost:8786", "tcp://"),
                                       ("", "tcp://")])
def test_bad_scheduler_addresses_are_refused_before_any_work(text, why, capsys):
    bag = str(ROOT / "bags" / "synthetic_rotation_100hz.mcap")
    assert main([bag, "--scheduler", text, "-q"]) == 2
    assert why in capsys.readouterr().err


def test_scheduler_does_not_combine_with_jobs_or_live(capsys):
    bag = str(ROOT / "bags" / "synthetic_rotation_100hz.mcap")
    assert main([bag, "--scheduler", "local:2", "--jobs", "2"]) == 2
    assert "does not combine with --jobs" in capsys.readouterr().err
    assert executors.parse_scheduler("local:3") == ("local", 3)
    assert executors.parse_scheduler(" tcp://10.0.0.1:8786 ") == ("tcp://10.0.0.1:8786", 0)


def _rows_without_timing(rep) -> list[dict]:
    return [{k: v for k, v in row.to_dict().items() if k not in TIMING} for row in rep.rows]


@pytest.mark.slow
def test_in_process_pool_and_dask_give_identical_results_on_the_bundled_bags():
    """The one loop over the inputs (executors.map_inputs) on each executor setting: the same rows, number for number
    (NaN where one is NaN), in input order."""
    from riann_ros import evaluation as ev
    from riann_ros.evaluation.executors import ExecutorSetting
    from riann_ros.evaluation.fleet import Scale
    from riann_ros.evaluation.session import EvalRun
    from riann_ros.evaluation.session import evaluate as run_session

    bags = tuple(sorted(str(p) for p in (ROOT / "bags").glob("synthetic_*.mcap")))
    settings = ev.EvalSettings(ev.parse_estimators("madgwick,vqf"), scenarios=[ev.REALISTIC, ev.AS_RECORDED],
                               conditions=[ev.parse_condition("none"), ev.parse_condition("bias:3,3,0")])
    got = {}
    for setting in (ExecutorSetting.in_process(), ExecutorSetting.pool(2), ExecutorSetting.dask("local:2")):
        rep = run_session(EvalRun(bags, settings, scale=Scale(setting)))
        assert not rep.failures, rep.failures
        got[setting.kind.value] = _rows_without_timing(rep)
    ref = got.pop("in-process")
    assert len(ref) == len(bags) * 2 * 2 * 2  # inputs × estimators × scenarios × conditions
    assert [r["source"] for r in ref[::8]] == list(bags)
    for kind, rows_ in got.items():
        assert len(rows_) == len(ref), kind
        for a, b in zip(ref, rows_, strict=True):
            assert a.keys() == b.keys(), kind
            for k in a:
                same = a[k] == b[k] or (isinstance(a[k], float) and math.isnan(a[k]) and math.isnan(b[k]))
                assert same, (kind, a["sequence"], a["estimator"], k, a[k], b[k])


def test_a_runner_of_this_process_is_refused_on_another_executor(tmp_path):
    """A runner given to a run (the live DDS replay is one) lives in this process: a pool or cluster setting with one
    is refused before any work, saying so."""
    from riann_ros import evaluation as ev
    from riann_ros.evaluation.executors import ExecutorSetting, InProcess, LocalPool, map_inputs
    from riann_ros.evaluation.fleet import Fleet, Scale

    settings = ev.EvalSettings(ev.parse_estimators("madgwick"))
    bags = [str(ROOT / "bags" / "synthetic_rotation_100hz.mcap")] * 2
    with pytest.raises(ev.EvalError, match="runs in-process only, not pool"):
        Fleet(Scale(ExecutorSetting.pool(2)), bags, settings, runner=ev.OfflineRunner())
    with pytest.raises(ev.EvalError, match="runs in-process only"):
        map_inputs(ev.evaluate_source, list(enumerate(bags)), settings, LocalPool(2), lambda i, r: None,
                   runner=ev.OfflineRunner())
    with Fleet(Scale(ExecutorSetting.pool(2)), bags, settings) as fleet:  # without a runner: the pool
        assert isinstance(fleet.executor(2), LocalPool) and fleet.executor(2).jobs == 2
        assert isinstance(fleet.executor(1), InProcess)  # one input: nothing to share
    with Fleet(Scale(ExecutorSetting.in_process()), bags, settings, runner=ev.OfflineRunner()) as fleet:
        assert isinstance(fleet.executor(2), InProcess)


@pytest.mark.parametrize("fields, why", [
    ({"kind": "pool", "jobs": 0}, "pool takes N >= 1"),
    ({"kind": "in-process", "jobs": 2}, "the others 1"),
    ({"kind": "dask"}, "a Dask cluster needs one"),
    ({"kind": "in-process", "scheduler": "local:2"}, "a scheduler belongs to a Dask cluster"),
    ({"kind": "dask", "scheduler": "local:0"}, "N >= 1"),
])
def test_an_executor_setting_that_does_not_fit_its_kind_is_refused(fields, why):
    from riann_ros.evaluation.executors import ExecutorKind, ExecutorSetting

    with pytest.raises(ValueError, match=why):
        ExecutorSetting(**{**fields, "kind": ExecutorKind(fields["kind"])})
