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
from riann_ros.evaluation.names import unique_names
from riann_ros.evaluation.report import Report
from riann_ros.evaluation.results import EvalSettings, Progress
from riann_ros.evaluation.run import evaluate_sources
from riann_ros.evaluation.runners import Runner
from riann_ros.evaluation.scenarios import REALISTIC


@dataclass(frozen=True)
class EvalRun:
    """What to evaluate: the inputs, the settings, the worker processes, and the grids to tune first."""

    sources: tuple[str, ...]
    settings: EvalSettings
    jobs: int = 1  # worker processes (one per input) for the in-process runner
    tune: tuple[str, ...] = ()  # tuning specs, NAME or NAME:PARAM=V1/V2/...; each best spec joins the estimators
    tune_scenario: str = REALISTIC  # the scenario whose mean RMSE the tuning minimises
    command: str = ""  # how the run was asked for (results.json: settings.command)


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


def evaluate(run: EvalRun, runner: Runner | None = None, hooks: Hooks | None = None,
             started: float | None = None) -> Report:
    """Tune the grids of ``run.tune`` (each best spec is added to the estimators unless one of that label is there),
    then evaluate every input (``runner``: None in-process, or e.g. the live DDS runner), each under a name of its own
    (:func:`~riann_ros.evaluation.names.unique_names`); the report with the time
    it took since ``started`` (a ``time.perf_counter()`` value; None: now, e.g. earlier when the runner's start-up
    counts). EvalError when the run cannot go on; an input that fails is a failure in the report."""
    hooks = hooks or Hooks()
    t0 = time.perf_counter() if started is None else started
    sources = list(run.sources)
    settings = replace(run.settings, estimators=list(run.settings.estimators))
    tuning = []
    for text in run.tune:
        hooks.tuning(text)
        best, spec = tune(text, sources, run.tune_scenario, settings.seed, run.jobs, hooks.progress(len(sources)),
                          like=settings)
        tuning.append(best)
        hooks.tuned(best)
        if spec.label not in {e.label for e in settings.estimators}:
            settings.estimators.append(spec)
    results = evaluate_sources(sources, settings, run.jobs, hooks.progress(len(sources)), runner)
    unique_names(results)  # two inputs never print as one (each renamed result warns)
    return Report(run.command, sources, settings, results, time.perf_counter() - t0, run.jobs, tuning)
