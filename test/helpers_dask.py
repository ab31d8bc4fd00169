"""A real Dask cluster on this machine for the tests: ``dask scheduler`` and ``dask worker`` processes (the venv's
commands, as a user starts them) over TCP on localhost, on free ports; each process in a session of its own, so a
test can kill one worker (its nanny and worker process) as a crash would."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import time
from pathlib import Path

from conftest import executable, wait_for


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class DaskProcesses:
    """A scheduler and named workers (``dask worker --nthreads 1``, started in ``cwd``); logs in ``logs``."""

    def __init__(self, logs: Path, cwd: Path) -> None:
        self.logs, self.cwd = logs, cwd
        self.port = free_port()
        self.address = f"tcp://127.0.0.1:{self.port}"
        self.procs: dict[str, subprocess.Popen] = {}
        self._start("scheduler", ["scheduler", "--host", "127.0.0.1", "--port", str(self.port),
                                  "--dashboard-address", f"127.0.0.1:{free_port()}"])

    def _start(self, name: str, args: list[str]) -> None:
        log = (self.logs / f"dask-{name}.log").open("w")
        self.procs[name] = subprocess.Popen([str(executable("dask")), *args], stdout=log, stderr=subprocess.STDOUT,
                                            cwd=self.cwd, start_new_session=True, env=os.environ.copy())

    def add_worker(self, name: str) -> None:
        self._start(name, ["worker", self.address, "--nthreads", "1", "--name", name, "--no-dashboard",
                           "--host", "127.0.0.1", "--local-directory", str(self.logs / f"{name}-space")])

    def client(self):
        from distributed import Client

        return Client(self.address, timeout="30s")

    def wait_workers(self, n: int, timeout: float = 120.0) -> None:
        with self.client() as c:
            c.wait_for_workers(n, timeout=timeout)

    def kill(self, name: str) -> None:
        """SIGKILL the named process and its children (a worker's nanny and worker process: a machine lost)."""
        p = self.procs.pop(name)
        os.killpg(p.pid, signal.SIGKILL)
        p.wait(30)

    def log(self, name: str) -> str:
        return (self.logs / f"dask-{name}.log").read_text()

    def close(self) -> None:
        for name in [n for n in self.procs if n != "scheduler"] + ["scheduler"]:
            p = self.procs.pop(name, None)
            if p is None or p.poll() is not None:
                continue
            os.killpg(p.pid, signal.SIGTERM)
            try:
                p.wait(20)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait(10)


def start_cluster(logs: Path, cwd: Path, workers: int = 2) -> DaskProcesses:
    """A scheduler with ``workers`` workers, every one of them joined."""
    cluster = DaskProcesses(logs, cwd)
    try:
        wait_for(lambda: "Scheduler at:" in cluster.log("scheduler"), 60, "the Dask scheduler", period=0.2)
        for k in range(workers):
            cluster.add_worker(f"w{k + 1}")
        cluster.wait_workers(workers)
    except BaseException:
        cluster.close()
        raise
    time.sleep(0.2)
    return cluster
