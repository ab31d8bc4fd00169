"""The Dask cluster executor of ``riann-bag-eval --scheduler`` (ROS-free; :mod:`distributed`, an optional
dependency): one task per input on the workers of a scheduler of one's own (``tcp://HOST:PORT``) or of a local
cluster (``local:N``), as :class:`DaskCluster`.

A cluster lost mid-run is one line, never a library traceback: Dask's own log (its errors and their tracebacks) goes
to a log file (``OUT/dask.log`` with an output folder), and a lost scheduler, or every worker gone for
:data:`WORKER_WAIT_S`, raises :class:`ClusterLost` naming it (the run keeps the inputs it finished:
:class:`riann_ros.evaluation.fleet.Fleet` says where and what to run next). A worker lost while others remain is a
note naming it: the scheduler runs its input again elsewhere. Stopped (Ctrl-C, an error), the run cancels its tasks
and restarts the workers still running one, so that no task of it keeps running on the cluster.
"""

from __future__ import annotations

import logging
import os
import socket
import tempfile
import time
import uuid
from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any

from riann_ros.evaluation.errors import EvalError, RunStopped
from riann_ros.evaluation.executors import Item, Results, Unit, failure, parse_scheduler, require_dask
from riann_ros.evaluation.results import EvalSettings, SequenceResult

WORKER_WAIT_S = 60.0  # how long a run waits for the first worker of a cluster, and for one after every worker left
POLL_S = 0.2  # how often a run looks for finished tasks, the scheduler's connection and its workers
WATCH_S = 1.0  # how often it asks the scheduler for its workers
RESTART_S = 30.0  # how long a stopped run waits for the workers it restarts (a task of it running there)
# a local cluster's settings (for a cluster of your own, the same as DASK_* variables of dask scheduler / dask worker):
# no statistical profiler on the workers (it samples the task's stack every 10 ms, about a tenth of the CPU of an
# estimator run), and a task handed to a worker only when it has a free thread, as a --jobs pool does (a long input
# queued behind another on a busy worker while the other idles is the tail of a run of few inputs)
LOCAL_CONFIG = {"distributed.worker.profile.enabled": False, "distributed.scheduler.worker-saturation": 1.0}
MIN_WINDOW = 64  # inputs submitted to a cluster ahead of those finished (more with more than 16 worker threads)


def on_worker(unit: Unit, source: str, settings: EvalSettings) -> SequenceResult:
    """The unit on a cluster worker: an input the worker cannot see fails at once, naming the worker, its host and
    folder (workers read the inputs by path, so every worker needs them at the same path: a shared filesystem)."""
    if not os.path.exists(source):
        where = f"{socket.gethostname()}:{os.getcwd()}"
        return failure(source, f"not found on the Dask worker at {where} (workers read inputs by path: every worker "
                       "must see it at the same path, e.g. on a shared filesystem; a relative path is relative to the "
                       "folder the worker was started in)")
    return unit(source, settings)


def _worker_probe() -> str:
    """Run on every worker before any work: riann_ros is importable there (it is, if this runs) and its version."""
    from riann_ros import __version__

    return __version__


class ClusterLost(RunStopped):
    """The cluster is gone mid-run (its scheduler, or every worker for :data:`WORKER_WAIT_S`); the text names it."""


class _DaskLog:
    """Dask's log (the ``distributed`` loggers and the event loop's) into ``path`` instead of the console, while a
    cluster is open: its errors come with library tracebacks that are no message for a user."""

    NAMES = ("distributed", "tornado", "asyncio", "bokeh")

    def __init__(self, path: Path) -> None:
        self.path = path
        self.handler = logging.FileHandler(path)
        self.handler.setFormatter(logging.Formatter("%(asctime)s - %(name)s - %(levelname)s - %(message)s"))
        self.saved: list[tuple[logging.Logger, list[logging.Handler], bool]] = []
        names = [n for n in logging.root.manager.loggerDict if n.split(".")[0] in self.NAMES]
        for name in sorted({*self.NAMES, *names}):
            lg = logging.getLogger(name)
            if name in self.NAMES or lg.handlers:
                self.saved.append((lg, list(lg.handlers), lg.propagate))
                for h in list(lg.handlers):
                    lg.removeHandler(h)
                lg.addHandler(self.handler)
                lg.propagate = False

    def close(self) -> None:
        for lg, handlers, propagate in self.saved:
            lg.removeHandler(self.handler)
            for h in handlers:
                lg.addHandler(h)
            lg.propagate = propagate
        self.handler.close()


class DaskCluster(AbstractContextManager["DaskCluster"]):
    """A Dask cluster: ``tcp://HOST:PORT`` (a scheduler started with ``dask scheduler``, workers with ``dask worker``)
    or ``local:N`` (a cluster of N single-threaded worker processes on this machine, started and stopped here).

    Each input is one task; Dask re-runs the task of a worker that dies on another worker (up to the scheduler's
    ``distributed.scheduler.allowed-failures``, 3 by default), after which the input fails as ``worker died``.
    ``note`` gets one-line messages (the dashboard's address, a worker lost); Dask's log goes to ``log`` (a
    temporary file when None; :attr:`log_path`) while the cluster is open."""

    def __init__(self, address: str, note: Callable[[str], None] | None = None, log: Path | None = None) -> None:
        require_dask()
        from distributed import Client, LocalCluster

        self.address, n = parse_scheduler(address)
        self.note = note or (lambda _: None)
        if log is None:
            fd, name = tempfile.mkstemp(prefix="riann_dask_", suffix=".log")
            os.close(fd)
            log = Path(name)
        self.log_path = log
        self._log: _DaskLog | None = _DaskLog(log)
        self._cluster: Any = None
        self.workers: dict[str, str] = {}  # address → name of the workers seen
        try:
            if n:
                import dask

                with dask.config.set(LOCAL_CONFIG):
                    self._cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                                 silence_logs=logging.ERROR)
                self.client: Any = Client(self._cluster)
            else:
                self.client = Client(self.address, timeout="20s")
        except (OSError, TimeoutError) as exc:
            self.close()
            raise EvalError(f"cannot reach the Dask scheduler at {self.address}: {exc}") from exc
        self._check_workers()

    def _check_workers(self) -> None:
        try:
            self.client.wait_for_workers(1, timeout=WORKER_WAIT_S)
        except TimeoutError as exc:
            self.close()
            raise EvalError(f"no Dask worker joined the scheduler at {self.address} within {WORKER_WAIT_S:.0f} s: "
                            f"start one with: dask worker {self.address}") from exc
        try:
            versions = self.client.run(_worker_probe)
        except Exception as exc:
            self.close()
            raise EvalError(f"a Dask worker cannot run riann_ros ({type(exc).__name__}: {exc}): install the same "
                            "riann_ros on every worker (pip install 'riann_ros[cluster]')") from exc
        from riann_ros import __version__

        other = {w: v for w, v in versions.items() if v != __version__}
        if other:
            self.close()
            raise EvalError(f"Dask workers with another riann_ros than this one ({__version__}): "
                            + ", ".join(f"{w} {v}" for w, v in other.items()))
        self.learn_names()
        link = self.client.dashboard_link if self._dashboard() else "none (pip install bokeh)"
        self.note(f"Dask cluster {self.address}: {len(versions)} worker(s); dashboard {link}")

    def _dashboard(self) -> bool:
        try:
            return "dashboard" in self.client.scheduler_info().get("services", {})
        except Exception:
            return False

    def learn_names(self) -> None:
        """The names of the workers there now (kept for those that leave)."""
        info = self.client.scheduler_info().get("workers", {})
        self.workers.update({addr: str(w.get("name", addr)) for addr, w in info.items()})

    def map(self, unit: Unit, items: Sequence[Item], settings: EvalSettings) -> Results:
        """One task per input, at most :meth:`window` of them on the scheduler at a time (a new one as each
        finishes), so a corpus of any size costs the scheduler and this process the same. ClusterLost when the
        scheduler, or every worker, is gone; stopped, the tasks left are cancelled (:meth:`_stop`)."""
        from distributed import as_completed

        run = uuid.uuid4().hex[:12]
        todo = iter(items)
        futures: dict[str, tuple[int, str, Any]] = {}
        finished = as_completed()

        def submit() -> None:
            item = next(todo, None)
            if item is not None:
                fut = self.client.submit(on_worker, unit, item[1], settings, key=f"riann-eval-{run}-{item[0]}",
                                         pure=False)
                futures[fut.key] = (item[0], item[1], fut)
                finished.add(fut)

        for _ in range(self.window()):
            submit()
        watch = _Watch(self)
        try:
            while futures:
                batch = finished.next_batch(block=False)
                if not batch:
                    watch.check()
                    time.sleep(POLL_S)
                for fut in batch:
                    i, src, _ = futures.pop(fut.key)
                    res = self._result(fut, src)
                    fut.release()
                    submit()
                    yield i, res
        finally:
            if futures:  # interrupted: the cluster drops what is left of this run
                self._stop(run, [f for _, _, f in futures.values()])

    def _stop(self, run: str, left: list[Any]) -> None:
        """Cancel the run's tasks left, then restart the workers still running one of them (Dask cannot stop a
        running task: its worker's nanny starts a fresh worker process), so none keeps running on the cluster."""
        if self.client.status != "running":
            return
        try:
            busy = [addr for addr, keys in self.client.processing().items()
                    if any(str(k).startswith(f"riann-eval-{run}-") for k in keys)]
            self.client.cancel(left)
            if busy and self._cluster is None:  # a local cluster's workers stop with it
                self.client.restart_workers(busy, timeout=RESTART_S, raise_for_error=False)
        except Exception as exc:  # the cluster going away meanwhile: nothing left running there
            logging.getLogger("distributed").warning("stopping the run's tasks: %r", exc)

    def window(self) -> int:
        """Tasks in flight: enough to keep every worker thread busy with a queue behind it."""
        try:
            threads = sum(self.client.nthreads().values())
        except Exception:
            threads = 0
        return max(MIN_WINDOW, 4 * threads)

    def _result(self, fut: Any, src: str) -> SequenceResult:
        from distributed import KilledWorker

        try:
            res: SequenceResult = fut.result()
            return res
        except KilledWorker:
            return failure(src, "worker died: every Dask worker that ran this input died before it finished (the "
                           "scheduler's allowed-failures were used up; out of memory?)")
        except Exception as exc:
            if self.client.status != "running" or "scheduler-connection-lost" in str(exc):
                raise ClusterLost(self.lost_scheduler()) from exc
            return failure(src, f"worker failed: {type(exc).__name__}: {exc}")

    def lost_scheduler(self) -> str:
        return f"the Dask scheduler at {self.address} was lost mid-run (the connection to it closed)"

    def close(self) -> None:
        for part in (getattr(self, "client", None), self._cluster):
            if part is not None:
                try:
                    part.close()
                except Exception:  # a cluster that is already gone
                    pass
        self._cluster = None
        if self._log is not None:
            self._log.close()
            self._log = None

    def __exit__(self, *exc: object) -> None:
        self.close()


class _Watch:
    """What a running map keeps an eye on between finished tasks: the scheduler's connection (ClusterLost when it
    closed) and its workers (each that leaves a note naming it; ClusterLost when none is left for
    :data:`WORKER_WAIT_S`)."""

    def __init__(self, cluster: DaskCluster) -> None:
        self.c = cluster
        self.seen = set(cluster.workers)
        self.next = time.monotonic() + WATCH_S
        self.alone_since: float | None = None  # no worker since then

    def check(self) -> None:
        c = self.c
        if c.client.status in ("closing", "closed", "failed"):
            raise ClusterLost(c.lost_scheduler())
        if time.monotonic() < self.next or c.client.status != "running":
            return
        self.next = time.monotonic() + WATCH_S
        try:
            now = set(c.client.nthreads())
        except Exception:  # the scheduler going away: the futures say so
            return
        if now - self.seen:
            c.learn_names()
        for addr in sorted(self.seen - now):
            c.note(f"warning: Dask worker {c.workers.get(addr, addr)} ({addr}) left the cluster mid-run: the "
                   "scheduler runs its input again on another worker")
        self.seen = now
        if now:
            self.alone_since = None
            return
        self.alone_since = self.alone_since or time.monotonic()
        if time.monotonic() - self.alone_since > WORKER_WAIT_S:
            gone = ", ".join(sorted(set(c.workers.values())))
            raise ClusterLost(f"every Dask worker of the scheduler at {c.address} left mid-run ({gone}) and none "
                              f"joined within {WORKER_WAIT_S:.0f} s")
