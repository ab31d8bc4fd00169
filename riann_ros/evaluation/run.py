"""The one evaluation pipeline (ROS-free): source → scenario → estimators → scores.

For each input and rate, a :class:`~riann_ros.evaluation.sources.Source` yields chunks (a bag chunk by
chunk; a BROAD file or a resampled recording as one chunk); after a first pass
(:func:`~riann_ros.evaluation.first_pass.summarise`) each chunk goes through every scenario's
:class:`~riann_ros.evaluation.scenarios.ScenarioPlan`, then each condition's perturbations
(:mod:`~riann_ros.evaluation.perturb`), into a runner, and the runner's estimates into one
:class:`~riann_ros.evaluation.scoring.Accumulator` per condition × scenario × estimator. A whole recording is
the one-chunk case of the same code, so streamed and whole evaluations cannot disagree.

The runner is where the estimates come from:

* :class:`~riann_ros.evaluation.runners.OfflineRunner` (default) runs every estimator in-process through
  :class:`riann_ros.stream.EstimatorStream` with the sequence's rate as ``nominal_rate``: the very code
  path of the ROS node, so offline scores are node scores. Its runs can be fed alternately, so one pass
  over a bag serves all scenarios.
* :class:`~riann_ros.evaluation.live.LiveRunner` replays the sequences over DDS to the estimator nodes (through
  the ROS layer's replay, :mod:`riann_ros.ros.dds_replay`); one replay at a time (a pass per scenario), in this
  process only.
* :class:`~riann_ros.evaluation.runners.RecordedRunner` serves the estimates a user's own filter recorded in the bag
  (``--estimate-topic``), which the source aligned onto each chunk's samples; they exist for the recording
  as it is only, so they join the as-recorded scenario, unperturbed, at the native rate, beside the other
  runner's estimators.

What a run is asked and gives (settings, rows): :mod:`~riann_ros.evaluation.results`.
"""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

from riann_ros.evaluation.errors import EvalError, RunStopped
from riann_ros.evaluation.executors import Executor, InProcess, map_inputs
from riann_ros.evaluation.first_pass import Summary, summarise
from riann_ros.evaluation.health import StreamHealth
from riann_ros.evaluation.input_hints import BROAD_SUFFIXES
from riann_ros.evaluation.rest import NO_REST_WARNING, Rest
from riann_ros.evaluation.results import EvalSettings, Progress, SequenceResult
from riann_ros.evaluation.runners import OfflineRunner, Runner
from riann_ros.evaluation.scenario_run import ScenarioRun
from riann_ros.evaluation.scenarios import AS_RECORDED, ScenarioPlan
from riann_ros.evaluation.sources import Source, open_source, read_whole
from riann_ros.evaluation.specs import EstimatorSpec
from riann_ros.recording import Recording


def _plan_runs(summary: Summary, settings: EvalSettings, name: str, native: bool,
               recorded: list[EstimatorSpec]) -> list[ScenarioRun]:
    """One run per condition × scenario (series for the conditions to plot, estimates for the very first run). The
    time offset is searched in one scenario per condition: as-recorded when evaluated (the stamps as they are),
    else the first (the paper's scenarios do not change the stamps). An input without a reference runs as recorded
    only (the paper's scenarios start and de-bias by the reference's score mask), with series whenever plots are
    asked for (its overlay figure)."""
    free = not summary.has_reference
    scenarios = [AS_RECORDED] if free else settings.scenarios
    want_series = native and settings.series_for is not None and (free or settings.series_for in ("*", "all", name))
    plotted = settings.series_conditions
    offset_scenario = AS_RECORDED if AS_RECORDED in scenarios else scenarios[0]
    runs = []
    for c, condition in enumerate(settings.conditions):
        for s, scn in enumerate(scenarios):
            # recorded estimates exist for the recording as it is only: as-recorded, unperturbed, own rate
            served = recorded if native and scn == AS_RECORDED and not condition.parts else []
            runs.append(ScenarioRun(ScenarioPlan(scn, summary, settings.seed), condition, settings, name,
                                    want_series and (plotted is None or condition.label in plotted),
                                    native and settings.keep_estimates and c == s == 0,
                                    served, offsets=scn == offset_scenario, free=free))
    return [r for r in runs if r.specs]


def _summarise(src: Source, rate: float | None, settings: EvalSettings, res: SequenceResult,
               native_rest: Rest | None = None) -> Summary:
    """The first pass; names the result and warns when a scenario would remove a bias but there is no rest.
    ``native_rest``: the rest detected at the recording's own rate, used for the resampled ones."""
    summary = summarise(src, settings.rest if settings.rest is not None or rate is None else native_rest)
    if not res.name:
        res.name, res.dataset, res.citation = summary.name, summary.dataset, summary.citation
    res.has_reference = summary.has_reference
    if not summary.has_reference:
        if AS_RECORDED not in settings.scenarios:
            _warn(res, f"{res.name}: no reference orientation: evaluated in the as-recorded scenario, the only one "
                  "without a reference")
        return summary
    if not summary.rest.found and any(s != AS_RECORDED for s in settings.scenarios):
        rate_note = "" if rate is None else f" (resampled to {rate:g} Hz)"
        _warn(res, f"{res.name}{rate_note}: {NO_REST_WARNING}")
    return summary


def _evaluate_rate(src: Source, rate: float | None, settings: EvalSettings, runner: Runner,
                   res: SequenceResult, native_rest: Rest | None = None) -> None:
    summary = _summarise(src, rate, settings, res, native_rest)
    runs = _plan_runs(summary, settings, res.name, rate is None, settings.recorded_for(src.path))
    for run in runs:
        res.scenarios.setdefault(run.plan.scenario, run.plan.info.to_dict())
    rate_hz = round(summary.rate_all, 3)
    health = _Health(summary, settings.seed) if rate is None else None
    for group in [runs] if runner.interleaved else [[r] for r in runs]:
        _one_pass(src, group, runner, health)
        if health is not None:
            res.health, health = health.result(), None
        for run in group:
            _collect(run, res, rate, rate_hz, runner.mode)


def _collect(run: ScenarioRun, res: SequenceResult, rate: float | None, rate_hz: float, mode: str) -> None:
    """A finished run's rows, series and estimates into ``res``."""
    res.rows.extend(run.rows(res, rate, rate_hz, mode))
    if run.series:
        run.keep_series(res)
    if run.estimates is not None:
        run.keep_estimates(res)


def _one_pass(src: Source, group: list[ScenarioRun], runner: Runner, health: _Health | None) -> None:
    """One pass over the source feeding every run of ``group`` (and the stream's health, when given)."""
    for run in group:
        run.begin(runner)
    offset = 0
    for chunk in src.chunks():
        for run in group:
            run.feed(chunk, offset)
        if health is not None:
            health.add(chunk, offset)
        offset += len(chunk)


class _Health:
    """The stream's health (:class:`~riann_ros.evaluation.health.StreamHealth`) over the recording as the
    as-recorded scenario sees it (stamps shifted off zero as for the estimators)."""

    def __init__(self, summary: Summary, seed: int) -> None:
        self.plan = ScenarioPlan(AS_RECORDED, summary, seed)
        self.health = StreamHealth(summary.rate_all, self.plan.first_stamp, summary.n)

    def add(self, chunk: Recording, offset: int) -> None:
        rec = self.plan.apply(chunk, offset)
        if rec is not None:
            self.health.add(rec)

    def result(self) -> dict:
        return self.health.result()


def _warn(res: SequenceResult, text: str) -> None:
    if text not in res.warnings:
        res.warnings.append(text)


def evaluate_source(source: str | os.PathLike[str], settings: EvalSettings, runner: Runner | None = None,
                    recording: Recording | None = None) -> SequenceResult:
    """Every rate × scenario × estimator on one input; any problem ends up in ``result.error`` naming it, except
    one no input can get past (:class:`~riann_ros.evaluation.errors.RunStopped`), which stops the run.

    ``source`` is a bag (``.mcap``, ``.db3``, a bag directory) or a BROAD trial file. Bags at their own
    rate are read chunk by chunk; BROAD files, and inputs that are also resampled (``settings.rates``),
    are read whole once. ``recording``: the input already in memory (``source`` then only names it).
    With ``settings.salvage``, a bag cut off by a crash is scored as far as it is readable: from a repaired copy
    in a temporary folder (:func:`riann_ros.bagio.repair.repair`), with a warning saying how much that is.
    """
    if settings.salvage and recording is None and Path(source).suffix.lower() not in BROAD_SUFFIXES:
        from riann_ros.bagio import repair

        if repair.is_truncated(source):
            return _evaluate_salvaged(source, settings, runner)
    return _evaluate_source(source, settings, runner, recording)


def _evaluate_salvaged(source: str | os.PathLike[str], settings: EvalSettings,
                       runner: Runner | None) -> SequenceResult:
    """:func:`evaluate_source` of the readable part of a cut-off bag (named as the bag itself in the results)."""
    import tempfile

    from riann_ros.bagio import repair

    src = Path(source)
    with tempfile.TemporaryDirectory(prefix=".riann_salvage.") as tmp:
        copy = Path(tmp) / (src.name if src.suffix == ".mcap" else f"{src.stem if src.is_file() else src.name}.mcap")
        try:
            t = repair.repair(src, copy)
        except Exception as exc:
            return SequenceResult(source=str(source), error=f"{source}: cannot salvage: {exc}")
        files = replace(settings.topics, files=tuple(
            replace(f, input=str(copy)) if f.input is not None and Path(f.input) == src else f
            for f in settings.topics.files))
        res = _evaluate_source(copy, replace(settings, topics=files), runner)
    res.source = str(source)
    for row in res.rows:
        row.source = str(source)
    if res.error:
        res.error = res.error.replace(str(copy), str(source))
    else:
        _warn(res, f"{res.name}: salvaged: {repair.describe(t)}; scored what was readable")
        res.salvaged = {"file_bytes": t.size, "expected_bytes": t.expected_size, "readable_bytes": t.readable_end,
                        "messages": t.total, "messages_per_topic": t.messages, "imu_samples_recorded": t.samples}
    return res


def _evaluate_source(source: str | os.PathLike[str], settings: EvalSettings, runner: Runner | None = None,
                     recording: Recording | None = None) -> SequenceResult:
    t0, c0 = time.perf_counter(), time.process_time()
    res = SequenceResult(source=str(source))
    runner = runner or OfflineRunner(settings.use_mag)
    try:
        base = recording
        whole = Path(source).suffix.lower() in BROAD_SUFFIXES or any(r is not None for r in settings.rates)
        if base is None and whole:
            base = read_whole(source, settings.topics)
        # resampled recordings use the rest found at the recording's own rate (resampling rings near steps)
        native_rest = None
        if base is not None and settings.rest is None and any(r is not None for r in settings.rates):
            native_rest = summarise(Source(source, base)).rest
        for rate in settings.rates:
            src = open_source(source, rate, base, settings.chunk, settings.topics)
            _evaluate_rate(src, rate, settings, runner, res, native_rest)
    except RunStopped:  # no input can get past it: the run stops
        raise
    except EvalError as exc:
        res = SequenceResult(source=str(source), error=str(exc))
    except Exception as exc:  # an estimator crash must not take the other inputs down
        res = SequenceResult(source=str(source), error=f"{source}: {type(exc).__name__}: {exc}")
    res.seconds = time.perf_counter() - t0
    res.cpu_seconds = time.process_time() - c0
    return res


def evaluate_sources(sources: Sequence[str], settings: EvalSettings, executor: Executor | None = None,
                     progress: Progress | None = None, runner: Runner | None = None) -> list[SequenceResult]:
    """Evaluate inputs on ``executor`` (:mod:`~riann_ros.evaluation.executors`; None: in this process, the only one
    that runs a given ``runner``); results in input order."""
    results: list[SequenceResult | None] = [None] * len(sources)

    def keep(i: int, res: SequenceResult) -> None:
        results[i] = res

    map_inputs(evaluate_source, list(enumerate(sources)), settings, executor or InProcess(), keep, progress, runner)
    return [r for r in results if r is not None]
