"""Where the evaluator's unit of work runs (ROS-free): one input with all its rates, scenarios, perturbation
conditions and estimators — :func:`riann_ros.evaluation.run.evaluate_source` — in this process
(:class:`InProcess`), in a pool of local worker processes (:class:`LocalPool`, ``--jobs``), or on a Dask cluster
(:class:`~riann_ros.evaluation.dask_cluster.DaskCluster`, ``--scheduler``). Which one is an explicit setting,
:class:`ExecutorSetting` (its :class:`ExecutorKind` and, when it was forced, why); the command line decides it
(:func:`riann_ros.cli.eval_executor.executor_setting`). Every executor gives the very same per-input results; they come
back as each input finishes, with the input's index, so a caller can keep them in input order and write each at
once. :func:`map_inputs` is the one loop over them.

The unit is a function ``unit(source, settings) -> SequenceResult`` of the module level (pickled by reference); an
executor treats its result as an opaque record. A unit that raises, or a worker that dies, gives a failure for that
input only: ``SequenceResult(source, error=...)``. A runner given to the run (the live DDS replay) is an object of
this process: only the in-process executor runs it.

Dask (:mod:`distributed`) is an optional dependency (``pip install 'riann_ros[cluster]'``); without it
:func:`require_dask` (and so the cluster executor) raises :class:`~riann_ros.evaluation.errors.EvalError` saying
how to install it.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Generator, Sequence
from contextlib import closing
from dataclasses import dataclass
from enum import Enum
from functools import partial
from typing import Protocol

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
