"""A run over many inputs (ROS-free): where its units of work run (:mod:`~riann_ros.evaluation.executors`: this
process, ``--jobs`` processes, a Dask cluster, as its :class:`~riann_ros.evaluation.executors.ExecutorSetting`
says) and, with an output folder, each finished input's result kept there
at once (:mod:`~riann_ros.evaluation.store`), so a run stopped at any point keeps what it finished and a resumed run
evaluates only the rest.

What the caller keeps in memory is bounded by the per-input summaries: each result without its plot series
(``SequenceResult.series``, thousands of points per curve), except the series the report plots — the first input's
in input order that has them (``--plot-sequence`` unset), or every sequence's that has them (a name, or ``all``).
The stored shards hold exactly what is kept, so a resumed run writes the same files as an uninterrupted one.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from riann_ros.evaluation.dask_cluster import ClusterLost, DaskCluster
from riann_ros.evaluation.errors import RunStopped
from riann_ros.evaluation.executors import (
    Executor,
    ExecutorKind,
    ExecutorSetting,
    local_executor,
    map_inputs,
)
from riann_ros.evaluation.results import EvalSettings, Progress, SequenceResult
from riann_ros.evaluation.run import evaluate_source, evaluate_sources
from riann_ros.evaluation.runners import Runner
from riann_ros.evaluation.store import NEW, RESUME, ShardStore, fingerprint

Note = Callable[[str], None]
DASK_LOG = "dask.log"  # Dask's log in the output folder, while a run is on a cluster


@dataclass(frozen=True)
class Scale:
    """Where a run's inputs are evaluated and kept."""

    executor: ExecutorSetting = field(default_factory=ExecutorSetting)  # this process, a pool, a Dask cluster
    out: Path | None = None  # keep each finished input's result in out/shards as it comes (None: in memory only)
    mode: str = NEW  # for out: store.NEW, store.REPLACE (--force) or store.RESUME (--resume)


class _Kept:
    """The results a run keeps, by input index: each one's plot series only where the report plots them."""

    def __init__(self, n: int, series_for: str | None, store: ShardStore | None) -> None:
        self.results: list[SequenceResult | None] = [None] * n
        self.first_only = series_for == "*"  # the report plots the first input in input order that has series
        self.plotted: int | None = None  # that input, so far
        self.store = store

    def add(self, i: int, res: SequenceResult, stored: bool = False) -> None:
        """Keep input ``i``'s result (and write it into the shards unless ``stored`` already as it is)."""
        if res.series is not None and self.first_only:
            if self.plotted is not None and self.plotted < i:
                res = replace(res, series=None)
                stored = False
            else:
                if self.plotted is not None:  # an earlier input has series: the later one's are not plotted
                    self._put(self.plotted, replace(self._get(self.plotted), series=None))
                self.plotted = i
        if stored:
            self.results[i] = res
        else:
            self._put(i, res)

    def _get(self, i: int) -> SequenceResult:
        res = self.results[i]
        assert res is not None
        return res

    def _put(self, i: int, res: SequenceResult) -> None:
        self.results[i] = res
        if self.store is not None:  # with the estimates of --write-estimates, so that a resumed run writes them
            self.store.write(i, res)


class Fleet(AbstractContextManager["Fleet"]):
    """One run's executor and shard store, opened before any work: a runner (the live DDS replay) with an executor
    setting other than in-process is refused (EvalError), the store refuses an output folder it must not write into
    (:class:`~riann_ros.evaluation.store.RunMismatch`), the cluster is connected (EvalError when it cannot be)."""

    def __init__(self, scale: Scale, sources: Sequence[str], settings: EvalSettings, runner: Runner | None = None,
                 tune: Sequence[str] = (), tune_scenario: str = "", note: Note | None = None) -> None:
        scale.executor.check_runner(runner)
        self.scale, self.sources, self.runner = scale, list(sources), runner
        self.note = note or (lambda _: None)
        fp = fingerprint(settings, tune, tune_scenario)
        self.store = ShardStore(scale.out, fp, scale.mode, self.sources) if scale.out is not None else None
        dask = scale.executor.scheduler if scale.executor.kind is ExecutorKind.DASK else None
        log = scale.out / DASK_LOG if scale.out is not None else None
        self.cluster = DaskCluster(dask, self.note, log) if dask is not None else None

    def executor(self, n_inputs: int) -> Executor:
        """The executor for a pass over ``n_inputs`` inputs (the cluster, a pool, or this process)."""
        return self.cluster if self.cluster is not None else local_executor(self.scale.executor, n_inputs)

    def saved_tuning(self) -> Any:
        """The tuning a resumed run saved before (None: tune)."""
        return self.store.tuning() if self.store is not None and self.scale.mode == RESUME else None

    def save_tuning(self, tuning: Any) -> None:
        if self.store is not None:
            self.store.save_tuning(tuning)

    def evaluate(self, settings: EvalSettings, progress: Callable[[int], Progress | None]) -> list[SequenceResult]:
        """Every input not finished yet (``progress(n)``: the callback of a pass over n inputs); all results in
        input order."""
        if self.store is None:
            try:
                return evaluate_sources(self.sources, settings, self.executor(len(self.sources)),
                                        progress(len(self.sources)), self.runner)
            except ClusterLost as exc:
                log = self.cluster.log_path if self.cluster else "-"
                raise RunStopped(f"{exc}: nothing is kept without --out; run the command again once the cluster is "
                                 f"back, with --out to keep each input as it finishes (Dask's log: {log})") from exc
        kept = _Kept(len(self.sources), settings.series_for, self.store)
        earlier = self.store.load() if self.scale.mode == RESUME else {}
        for i in sorted(earlier):
            if not earlier[i].error:
                kept.add(i, earlier[i], stored=True)
        todo = [(i, s) for i, s in enumerate(self.sources) if kept.results[i] is None]
        if self.scale.mode == RESUME:
            self.note(f"resuming {self.scale.out}: {len(self.sources) - len(todo)} of {len(self.sources)} input(s) "
                      f"finished earlier; evaluating {len(todo)}")
        try:
            map_inputs(evaluate_source, todo, settings, self.executor(len(todo)), kept.add,
                       progress(len(todo)) if todo else None, self.runner)
        except ClusterLost as exc:
            done = sum(r is not None for r in kept.results)
            raise RunStopped(f"{exc}: the {done} input(s) finished are kept in {self.store.dir}; run the same command "
                             f"with --resume (same --out) to evaluate the other {len(self.sources) - done} once the "
                             f"cluster is back (Dask's log: {self.cluster.log_path if self.cluster else '-'})") from exc
        return [r for r in kept.results if r is not None]

    def close(self) -> None:
        if self.cluster is not None:
            self.cluster.close()

    def __exit__(self, *exc: object) -> None:
        self.close()

