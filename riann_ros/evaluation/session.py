"""One ``riann-bag-eval`` run as a library call (ROS-free): the inputs and typed settings in, a
:class:`~riann_ros.evaluation.report.Report` out; no command line, no printing. What a caller wants to hear while
the run goes on (a tuning search starting and ending, progress per pass over the inputs) comes through
:class:`Hooks`. The command (:mod:`riann_ros.cli.evaluate`) is a thin layer over :func:`evaluate`; from Python::

    from riann_ros.evaluation import EvalSettings, parse_estimators
    from riann_ros.evaluation.session import EvalRun, evaluate

    rep = evaluate(EvalRun(("bags/synthetic_rotation_100hz.mcap",), EvalSettings(parse_estimators("madgwick,vqf"))))
    for group in rep.summary:
        print(group.estimator, group.scenario, group.mean)
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

from riann_ros.evaluation.aggregate import tune
from riann_ros.evaluation.fleet import Fleet, Scale
from riann_ros.evaluation.names import unique_names
from riann_ros.evaluation.report import Report
from riann_ros.evaluation.results import EvalSettings, Progress
from riann_ros.evaluation.runners import Runner
from riann_ros.evaluation.scenarios import REALISTIC


@dataclass(frozen=True)
class EvalRun:
    """What to evaluate: the inputs, the settings, the grids to tune first, and where it runs (``scale``)."""

    sources: tuple[str, ...]
    settings: EvalSettings
    tune: tuple[str, ...] = ()  # tuning specs, NAME or NAME:PARAM=V1/V2/...; each best spec joins the estimators
    tune_scenario: str = REALISTIC  # the scenario whose mean RMSE the tuning minimises
    command: str = ""  # how the run was asked for (results.json: settings.command)
    scale: Scale = field(default_factory=Scale)  # the executor setting; results kept as they come (resume)


def _no_progress(total: int) -> Progress | None:
    return None


def _silent(_: Any) -> None:
    return None


@dataclass(frozen=True)
class Hooks:
    """What a caller hears while a run goes on; each does nothing unless given."""

    tuning: Callable[[str], None] = _silent  # the search of a tuning spec starts
    tuned: Callable[[dict[str, Any]], None] = _silent  # its result (aggregate.tune: the grid and its best)
    progress: Callable[[int], Progress | None] = field(default=_no_progress)  # the callback of a pass over N inputs
    note: Callable[[str], None] = _silent  # a one-line message (the cluster's dashboard, a resumed run)


def _tuned(run: EvalRun, settings: EvalSettings, fleet: Fleet, hooks: Hooks) -> list[tuple[dict[str, Any], Any]]:
    """Each tuning spec's result and best spec: searched now, or as a resumed run's earlier pass saved them."""
    tuned = fleet.saved_tuning()
    if tuned is not None:
        if tuned:
            hooks.note("tuning: the results the earlier run saved")
        return list(tuned)
    tuned = []
    for text in run.tune:
        hooks.tuning(text)
        tuned.append(tune(text, list(run.sources), run.tune_scenario, settings.seed, fleet.executor(len(run.sources)),
                          hooks.progress(len(run.sources)), like=settings))
        hooks.tuned(tuned[-1][0])
    if tuned:
        fleet.save_tuning(tuned)
    return tuned


def evaluate(run: EvalRun, runner: Runner | None = None, hooks: Hooks | None = None,
             started: float | None = None) -> Report:
    """Tune the grids of ``run.tune`` (each best spec is added to the estimators unless one of that label is there),
    then evaluate every input (``runner``: None, each input's own in-process runs, or e.g. the live DDS runner, which
    needs the in-process executor; ``run.scale``: the executor setting — this process, a pool, a Dask cluster — and
    each finished input kept in an output folder, where a resumed run finds what is done), each under a
    name of its own (:func:`~riann_ros.evaluation.names.unique_names`); the report with the time it took since
    ``started`` (a ``time.perf_counter()`` value; None: now, e.g. earlier when the runner's start-up counts).
    EvalError when the run cannot go on; an input that fails is a failure in the report.
    :class:`~riann_ros.evaluation.store.RunMismatch` (a ValueError) before any work for an output folder holding
    another run's shards."""
    hooks = hooks or Hooks()
    t0 = time.perf_counter() if started is None else started
    sources = list(run.sources)
    settings = replace(run.settings, estimators=list(run.settings.estimators))
    with Fleet(run.scale, sources, run.settings, runner, run.tune, run.tune_scenario, hooks.note) as fleet:
        tuned = _tuned(run, settings, fleet, hooks)
        for _, spec in tuned:
            if spec.label not in {e.label for e in settings.estimators}:
                settings.estimators.append(spec)
        results = fleet.evaluate(settings, hooks.progress)
    unique_names(results)  # two inputs never print as one (each renamed result warns)
    return Report(run.command, sources, settings, results, time.perf_counter() - t0, run.scale.executor.jobs,
                  [t for t, _ in tuned])
