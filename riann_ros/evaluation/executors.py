"""Where the evaluator's unit of work runs (ROS-free): one input with all its rates, scenarios, perturbation
conditions and estimators — :func:`riann_ros.evaluation.run.evaluate_source` — in this process
(:class:`InProcess`), in a pool of local worker processes (:class:`LocalPool`, ``--jobs``), or on a Dask cluster
(:class:`DaskCluster`, ``--scheduler``). Which one is an explicit setting, :class:`ExecutorSetting` (its
:class:`ExecutorKind` and, when it was forced, why); the command line decides it
(:func:`riann_ros.cli.eval_executor.executor_setting`). Every executor gives the very same per-input results; they come
back as each input finishes, with the input's index, so a caller can keep them in input order and write each at
once. :func:`map_inputs` is the one loop over them.

The unit is a function ``unit(source, settings) -> SequenceResult`` of the module level (pickled by reference); an
executor treats its result as an opaque record. A unit that raises, or a worker that dies, gives a failure for that
input only: ``SequenceResult(source, error=...)``. A runner given to the run (the live DDS replay) is an object of
this process: only the in-process executor runs it.

Dask (:mod:`distributed`) is an optional dependency (``pip install 'riann_ros[cluster]'``); without it
:class:`DaskCluster` raises :class:`~riann_ros.evaluation.errors.EvalError` saying how to install it.
"""

from __future__ import annotations

import os
import socket
import uuid
from collections.abc import Callable, Generator, Sequence
from contextlib import AbstractContextManager, closing
from dataclasses import dataclass
from enum import Enum
from functools import partial
from typing import Any, Protocol

from riann_ros.evaluation.errors import EvalError
from riann_ros.evaluation.results import EvalSettings, Progress, SequenceResult
from riann_ros.evaluation.runners import Runner

Unit = Callable[[str, EvalSettings], SequenceResult]
Item = tuple[int, str]  # (index in the input list, input path)
Results = Generator[tuple[int, SequenceResult], None, None]  # (index, result) as each input finishes
Keep = Callable[[int, SequenceResult], None]  # takes each finished input's (index, result)
INSTALL_HINT = ("--scheduler needs Dask's distributed scheduler: pip install 'riann_ros[cluster]' "
                "(or pip install -r requirements-cluster.txt from the source tree)")
LOCAL_PREFIX = "local:"
WORKER_WAIT_S = 60.0  # how long a run waits for the first worker of a cluster
# a local cluster's settings (for a cluster of your own, the same as DASK_* variables of dask scheduler / dask worker):
# no statistical profiler on the workers (it samples the task's stack every 10 ms, about a tenth of the CPU of an
# estimator run), and a task handed to a worker only when it has a free thread, as a --jobs pool does (a long input
# queued behind another on a busy worker while the other idles is the tail of a run of few inputs)
LOCAL_CONFIG = {"distributed.worker.profile.enabled": False, "distributed.scheduler.worker-saturation": 1.0}
MIN_WINDOW = 64  # inputs submitted to a cluster ahead of those finished (more with more than 16 worker threads)


class ExecutorKind(Enum):
    """Where a run's inputs are evaluated."""

    IN_PROCESS = "in-process"  # one after the other in this process
    POOL = "pool"  # local worker processes (--jobs N)
    DASK = "dask"  # a Dask cluster's workers (--scheduler)


RUNNER_IN_PROCESS = ("a runner given to the run (the live DDS replay) is an object of this process: it runs "
                     "in-process only")


@dataclass(frozen=True)
class ExecutorSetting:
    """Where a run's inputs are evaluated, chosen explicitly: in this process, in a pool of ``jobs`` local worker
    processes, or on the Dask cluster of ``scheduler`` (``tcp://HOST:PORT`` or ``local:N``); ``why``: the reason
    when the choice was forced (e.g. ``--live``, whose replay runs in this process). ValueError when the fields do
    not fit the kind."""

    kind: ExecutorKind = ExecutorKind.IN_PROCESS
    jobs: int = 1  # worker processes of a pool (1 otherwise)
    scheduler: str | None = None  # a Dask cluster's scheduler (None otherwise)
    why: str = ""

    def __post_init__(self) -> None:
        if self.jobs < 1 or (self.kind is not ExecutorKind.POOL and self.jobs != 1):
            raise ValueError(f"{self.kind.value}: {self.jobs} worker processes (a pool takes N >= 1, the others 1)")
        if (self.scheduler is not None) != (self.kind is ExecutorKind.DASK):
            raise ValueError(f"{self.kind.value}: a scheduler belongs to a Dask cluster, and a Dask cluster needs one")
        if self.scheduler is not None:
            parse_scheduler(self.scheduler)

    @classmethod
    def in_process(cls, why: str = "") -> ExecutorSetting:
        return cls(ExecutorKind.IN_PROCESS, why=why)

    @classmethod
    def pool(cls, jobs: int) -> ExecutorSetting:
        return cls(ExecutorKind.POOL, jobs=jobs)

    @classmethod
    def dask(cls, scheduler: str) -> ExecutorSetting:
        return cls(ExecutorKind.DASK, scheduler=scheduler)

    def check_runner(self, runner: Runner | None) -> None:
        """EvalError when a runner is given to a run that is not in this process."""
        if runner is not None and self.kind is not ExecutorKind.IN_PROCESS:
            raise EvalError(f"{RUNNER_IN_PROCESS}, not {self.kind.value}")


class Executor(Protocol):
    """Runs the unit on items, yielding ``(index, result)`` as each input finishes (in any order)."""

    def map(self, unit: Unit, items: Sequence[Item], settings: EvalSettings) -> Results:
        ...  # pragma: no cover


def failure(source: str, why: str) -> SequenceResult:
    """The result of an input whose unit did not return one."""
    return SequenceResult(source=str(source), error=f"{source}: {why}")


class InProcess:
    """One input after the other in this process (the only executor of a unit that is not picklable, e.g. one bound
    to the live DDS runner)."""

    def map(self, unit: Unit, items: Sequence[Item], settings: EvalSettings) -> Results:
        for i, src in items:
            yield i, unit(src, settings)


def _init_worker() -> None:
    import signal

    # Ctrl-C reaches the whole process group: the parent handles it and stops the workers
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # one core per worker: ONNX Runtime and BLAS would otherwise fight over the cores
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = "1"


class LocalPool:
    """``jobs`` worker processes on this machine (one input each at a time). A worker that dies fails the inputs it
    held with ``worker failed``; Ctrl-C stops the workers at once."""

    def __init__(self, jobs: int) -> None:
        self.jobs = jobs

    def map(self, unit: Unit, items: Sequence[Item], settings: EvalSettings) -> Results:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor, as_completed

        ctx = mp.get_context("spawn" if os.name == "nt" else "forkserver")
        pool = ProcessPoolExecutor(max_workers=self.jobs, mp_context=ctx, initializer=_init_worker)
        try:
            futures = {pool.submit(unit, src, settings): (i, src) for i, src in items}
            for fut in as_completed(futures):
                i, src = futures.pop(fut)
                try:
                    res = fut.result()
                except Exception as exc:  # a worker died
                    res = failure(src, f"worker failed: {exc}")
                yield i, res
        except BaseException:
            # Ctrl-C, an error, or the caller stopped: stop the workers now instead of waiting for their inputs
            procs = list(getattr(pool, "_processes", {}).values())
            pool.shutdown(wait=False, cancel_futures=True)
            for p in procs:
                if p.is_alive():
                    p.terminate()
            for p in procs:
                p.join(5)
            raise
        pool.shutdown(wait=True)


def local_executor(setting: ExecutorSetting, n_inputs: int) -> InProcess | LocalPool:
    """The executor of an in-process or pool setting for ``n_inputs`` inputs: a pool of ``setting.jobs`` processes
    when there is more than one input to share among more than one worker, else this process (one input or one
    worker gains nothing from worker processes; the results are the same)."""
    if setting.kind is ExecutorKind.DASK:
        raise ValueError("a Dask setting's executor is its cluster (DaskCluster)")
    if setting.kind is ExecutorKind.IN_PROCESS or setting.jobs <= 1 or n_inputs <= 1:
        return InProcess()
    return LocalPool(setting.jobs)


def map_inputs(unit: Unit, items: Sequence[Item], settings: EvalSettings, executor: Executor, keep: Keep,
               progress: Progress | None = None, runner: Runner | None = None) -> None:
    """The one loop over a run's inputs, whatever the executor: ``unit`` on every ``(index, input)`` item (bound to
    ``runner`` when one is given: in this process only, EvalError otherwise), each result handed to ``keep`` as it
    finishes, then to ``progress``. Stopped early (an error, Ctrl-C), the executor stops what is left."""
    if runner is not None:
        if not isinstance(executor, InProcess):
            raise EvalError(RUNNER_IN_PROCESS)
        unit = partial(unit, runner=runner)  # type: ignore[call-arg]
    with closing(executor.map(unit, items, settings)) as finished:
        for done, (i, res) in enumerate(finished, 1):
            keep(i, res)
            if progress:
                progress(done, len(items), res)


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


def parse_scheduler(text: str) -> tuple[str, int]:
    """``local:N`` → ("local", N); any other address (``tcp://HOST:8786``) → (address, 0). ValueError when bad."""
    text = text.strip()
    if text.startswith(LOCAL_PREFIX):
        n = text[len(LOCAL_PREFIX):]
        if not n.isdigit() or int(n) < 1:
            raise ValueError(f"--scheduler {text}: local:N needs N worker processes, N >= 1 (e.g. local:2)")
        return "local", int(n)
    if not text or "://" not in text:
        raise ValueError(f"--scheduler {text!r}: give the scheduler's address, tcp://HOST:PORT (dask scheduler prints "
                         "it; port 8786 by default), or local:N for a cluster of N workers on this machine")
    return text, 0


def require_dask() -> None:
    """EvalError with the install command when Dask's distributed scheduler is not installed."""
    try:
        import distributed  # noqa: F401
    except ImportError as exc:
        raise EvalError(f"{INSTALL_HINT} ({exc})") from exc


class DaskCluster(AbstractContextManager["DaskCluster"]):
    """A Dask cluster: ``tcp://HOST:PORT`` (a scheduler started with ``dask scheduler``, workers with ``dask worker``)
    or ``local:N`` (a cluster of N single-threaded worker processes on this machine, started and stopped here).

    Each input is one task; Dask re-runs the task of a worker that dies on another worker (up to the scheduler's
    ``distributed.scheduler.allowed-failures``, 3 by default), after which the input fails as ``worker died``.
    ``note`` gets one-line messages (the dashboard's address)."""

    def __init__(self, address: str, note: Callable[[str], None] | None = None) -> None:
        require_dask()
        from distributed import Client, LocalCluster

        self.address, n = parse_scheduler(address)
        self._cluster: Any = None
        try:
            if n:
                import logging

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
        self._check_workers(note)

    def _check_workers(self, note: Callable[[str], None] | None) -> None:
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
        if note is not None:
            link = self.client.dashboard_link if self._dashboard() else "none (pip install bokeh)"
            note(f"Dask cluster {self.address}: {len(versions)} worker(s); dashboard {link}")

    def _dashboard(self) -> bool:
        try:
            return "dashboard" in self.client.scheduler_info().get("services", {})
        except Exception:
            return False

    def map(self, unit: Unit, items: Sequence[Item], settings: EvalSettings) -> Results:
        """One task per input, at most :meth:`window` of them on the scheduler at a time (a new one as each
        finishes), so a corpus of any size costs the scheduler and this process the same."""
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
        try:
            for fut in finished:
                i, src, _ = futures.pop(fut.key)
                res = self._result(fut, src)
                fut.release()
                submit()
                yield i, res
        finally:
            if futures:  # interrupted: the cluster drops what is left of this run
                self.client.cancel([f for _, _, f in futures.values()])

    def window(self) -> int:
        """Tasks in flight: enough to keep every worker thread busy with a queue behind it."""
        try:
            threads = sum(self.client.nthreads().values())
        except Exception:
            threads = 0
        return max(MIN_WINDOW, 4 * threads)

    @staticmethod
    def _result(fut: Any, src: str) -> SequenceResult:
        from distributed import KilledWorker

        try:
            res: SequenceResult = fut.result()
            return res
        except KilledWorker:
            return failure(src, "worker died: every Dask worker that ran this input died before it finished (the "
                           "scheduler's allowed-failures were used up; out of memory?)")
        except Exception as exc:
            return failure(src, f"worker failed: {type(exc).__name__}: {exc}")

    def close(self) -> None:
        for part in (getattr(self, "client", None), self._cluster):
            if part is not None:
                try:
                    part.close()
                except Exception:  # a cluster that is already gone
                    pass
        self._cluster = None

    def __exit__(self, *exc: object) -> None:
        self.close()
