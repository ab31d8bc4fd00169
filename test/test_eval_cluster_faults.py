"""riann-bag-eval on a Dask cluster under faults (riann_ros.evaluation.dask_cluster), with a real ``dask scheduler``
and ``dask worker`` over TCP on localhost (test/helpers_dask.py): the scheduler killed mid-run is one line on
stderr naming it and ``--resume``, exit status 1, no library traceback (Dask's log in ``OUT/dask.log``), the inputs
finished kept; every worker lost is named, then the same; Ctrl-C cancels the run's tasks, so none keeps running on a
worker, exit status 130 with one line."""

from __future__ import annotations

import os
import signal
import subprocess
import threading
from pathlib import Path

import pytest

from conftest import executable, wait_for
from riann_ros import bagio
from riann_ros.cli.evaluate import main
from riann_ros.datasets.synthetic import generate
from riann_ros.evaluation import dask_cluster

pytest.importorskip("distributed")
from helpers_dask import DaskProcesses, start_cluster

ARGS = ["-e", "riann", "-s", "realistic", "--no-plots", "-q"]


@pytest.fixture(scope="module")
def long_bags(tmp_path_factory) -> list[Path]:
    """Three synthetic bags long enough (60 s at 1 kHz) that one worker is still busy when the first is kept."""
    d = tmp_path_factory.mktemp("long")
    return [bagio.write_recording(d / f"syn{k}.mcap", generate(rate=1000, duration=60, seed=k, start_s=1.0))
            for k in range(3)]


def _start(bags: list[Path], cluster: DaskProcesses, out: Path) -> subprocess.Popen:
    return subprocess.Popen([str(executable("riann-bag-eval")), *map(str, bags), *ARGS, "--scheduler",
                             cluster.address, "--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=os.environ.copy())


def _run_tasks(cluster: DaskProcesses) -> list[str]:
    """The run's tasks some worker is processing now."""
    with cluster.client() as c:
        return [str(k) for keys in c.processing().values() for k in keys if str(k).startswith("riann-eval-")]


@pytest.mark.slow
def test_the_scheduler_killed_mid_run_is_one_line_naming_it_and_resume(long_bags, tmp_path):
    cluster = start_cluster(tmp_path, tmp_path, workers=1)
    out = tmp_path / "out"
    try:
        p = _start(long_bags, cluster, out)
        wait_for(lambda: p.poll() is not None or any((out / "shards").glob("*.npz")), 300, "the first input kept",
                 period=0.05)
        assert p.poll() is None, "the run finished before its scheduler could be killed"
        cluster.kill("scheduler")
        stdout, stderr = p.communicate(timeout=120)
    finally:
        cluster.close()
    assert p.returncode == 1, stdout + stderr
    (line,) = [ln for ln in stderr.splitlines() if ln.strip()]
    assert line.startswith(f"riann-bag-eval: the Dask scheduler at {cluster.address} was lost mid-run"), line
    assert "--resume" in line and str(out / "dask.log") in line, line
    assert "Traceback" not in stderr
    assert (out / "dask.log").is_file()
    assert any((out / "shards").glob("*.npz")) and not (out / "results.csv").exists()


@pytest.mark.slow
def test_ctrl_c_cancels_the_runs_tasks_so_no_worker_keeps_running_one(long_bags, tmp_path):
    cluster = start_cluster(tmp_path, tmp_path, workers=1)
    out = tmp_path / "out"
    try:
        p = _start(long_bags, cluster, out)
        wait_for(lambda: p.poll() is not None or bool(_run_tasks(cluster)), 300, "a worker running a task",
                 period=0.2)
        assert p.poll() is None, "the run finished before it could be interrupted"
        p.send_signal(signal.SIGINT)
        stdout, stderr = p.communicate(timeout=120)
        wait_for(lambda: not _run_tasks(cluster), 5, "the worker idle after Ctrl-C", period=0.2)
    finally:
        cluster.close()
    assert p.returncode == 130, stdout + stderr
    (line,) = [ln for ln in stderr.splitlines() if ln.strip()]
    assert "interrupted" in line and "Traceback" not in stderr, stderr
    assert not (out / "results.csv").exists()


@pytest.mark.slow
def test_every_worker_lost_is_named_then_the_run_stops_with_resume(long_bags, tmp_path, monkeypatch, capsys):
    """The one worker killed mid-run: a warning naming it; none joins within WORKER_WAIT_S (3 s here): the run stops
    with one line naming the lost worker and --resume, exit status 1."""
    monkeypatch.setattr(dask_cluster, "WORKER_WAIT_S", 3.0)
    cluster = start_cluster(tmp_path, tmp_path, workers=1)
    out = tmp_path / "out"
    rc: list[int] = []
    try:
        run = threading.Thread(target=lambda: rc.append(main([*map(str, long_bags), *ARGS[:-1], "--scheduler",
                                                             cluster.address, "--out", str(out)])))
        run.start()
        wait_for(lambda: not run.is_alive() or bool(_run_tasks(cluster)), 300, "a worker running a task", period=0.2)
        assert run.is_alive(), "the run finished before its worker could be killed"
        cluster.kill("w1")
        run.join(120)
    finally:
        cluster.close()
    err = capsys.readouterr().err
    assert rc == [1], err
    assert "warning: Dask worker w1 (tcp://127.0.0.1:" in err and "left the cluster mid-run" in err
    last = err.strip().splitlines()[-1]
    assert f"every Dask worker of the scheduler at {cluster.address} left mid-run (w1)" in last, err
    assert "--resume" in last and "Traceback" not in err
