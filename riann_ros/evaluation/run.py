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
* :class:`riann_ros.cli.live.LiveRunner` replays the sequences over DDS to the estimator nodes; one
  replay at a time (a pass per scenario).
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

import numpy as np
from numpy.typing import NDArray

from riann_ros.evaluation.errors import EvalError
from riann_ros.evaluation.first_pass import Summary, summarise
from riann_ros.evaluation.input_hints import BROAD_SUFFIXES
from riann_ros.evaluation.offsets import OffsetSearch
from riann_ros.evaluation.perturb import Condition, Transform
from riann_ros.evaluation.rest import NO_REST_WARNING, Rest
from riann_ros.evaluation.results import (
    NATIVE,
    RECORDED,
    REFERENCE,
    SERIES_POINTS,
    EvalSettings,
    Progress,
    ResultRow,
    RunStats,
    SequenceResult,
)
from riann_ros.evaluation.runners import Joined, OfflineRunner, RecordedRunner, Run, Runner, run_sigmas
from riann_ros.evaluation.scenarios import AS_RECORDED, ScenarioPlan, sequence_seed
from riann_ros.evaluation.scoring import Accumulator, Score, error_deg, roll_pitch_deg
from riann_ros.evaluation.sources import Source, open_source, read_whole
from riann_ros.evaluation.specs import EstimatorSpec
from riann_ros.gate import GateConfig
from riann_ros.recording import Recording


class _ScenarioRun:
    """One condition × scenario of one sequence at one rate: the scenario plan, the condition's transforms, the
    runner's run and one accumulator per estimator."""

    def __init__(self, plan: ScenarioPlan, condition: Condition, slot: int, settings: EvalSettings, name: str,
                 series: bool, estimates: bool, recorded: list[EstimatorSpec] | None = None,
                 offsets: bool = False) -> None:
        self.plan = plan
        self.condition = condition
        self.slot = slot
        self.own = settings.estimators  # run by the runner
        self.recorded = recorded or []  # served from the bag
        self.specs = [*self.own, *self.recorded]
        rngs = [np.random.default_rng(sequence_seed(settings.seed, f"{name}:{condition.label}:{k}"))
                for k in range(len(condition.parts))]
        self.transforms: list[Transform] = condition.start(rngs)
        rate = plan.gate.nominal_rate
        self.gate = GateConfig.for_rate(condition.nominal_rate(rate)) if condition.parts else plan.gate
        self.acc = [Accumulator(settings.with_heading) for _ in self.specs]
        self.score_from_ns = plan.first_stamp + round(settings.score_from_s * 1e9)  # scored from this stamp on
        # the time offset that minimises e_α (one scenario per sequence × condition × rate: see _plan_runs)
        self.offsets = (OffsetSearch(len(self.specs), 1.0 / self.gate.nominal_rate, settings.offset_steps)
                        if offsets and settings.offset_steps > 0 else None)
        self.run: Run | None = None
        self.fed = 0  # samples fed so far
        length = plan.length * (condition.nominal_rate(rate) / rate if condition.parts else 1.0)
        self.step = settings.series_step if settings.series_step > 0 else max(1, -(-int(length) // SERIES_POINTS))
        self.series = series
        self.curves: list[list[NDArray[np.float32]]] = [[] for _ in self.specs]
        self.att: list[list[NDArray[np.float32]]] = [[] for _ in self.specs]
        self.att_ref: list[NDArray[np.float32]] = []
        self.t: list[NDArray[np.float32]] = []
        self.scored: list[NDArray[np.bool_]] = []
        self.estimates: list[tuple[NDArray[np.int64], list[NDArray[np.float64]]]] | None = [] if estimates else None

    def begin(self, runner: Runner) -> None:
        runs = [runner.start(self.own, self.gate, self.slot)] if self.own else []
        runs += [RecordedRunner().start(self.recorded, self.gate, self.slot)] if self.recorded else []
        self.run = runs[0] if len(runs) == 1 else Joined(runs)

    def feed(self, chunk: Recording, offset: int) -> None:
        rec = self.plan.apply(chunk, offset)
        for tr in self.transforms:
            if rec is None or not len(rec):
                return
            rec = tr(rec)
        if rec is None or not len(rec) or self.run is None:
            return
        qs = self.run.feed(rec)
        run = self.run
        sigmas = (run.sigmas([len(self.own), len(self.recorded)]) if isinstance(run, Joined)
                  else run_sigmas(run, len(self.specs)))
        mask = rec.score_mask & (rec.stamps_ns >= self.score_from_ns)  # --score-from
        for acc, q, sig in zip(self.acc, qs, sigmas, strict=True):
            acc.add(rec.quat_ref, mask, q, sig)
        if self.offsets is not None:
            self.offsets.add(rec.stamps_ns, rec.quat_ref, mask, qs)
        if self.series and rec.quat_ref is not None:
            self._add_series(rec, qs)
        if self.estimates is not None:
            self.estimates.append((rec.stamps_ns - self.plan.shift, qs))
        self.fed += len(rec)

    def _add_series(self, rec: Recording, qs: list[NDArray[np.float64]]) -> None:
        """Every ``step``-th sample (counted over the whole sequence): e_α, roll and pitch of each estimator, the
        reference's roll and pitch, time and score mask."""
        assert rec.quat_ref is not None
        pick = slice((-self.fed) % self.step, None, self.step)
        for curve, att, q in zip(self.curves, self.att, qs, strict=True):
            curve.append(error_deg(rec.quat_ref[pick], q[pick]).astype(np.float32))
            att.append(roll_pitch_deg(q[pick]).astype(np.float32))
        self.att_ref.append(roll_pitch_deg(rec.quat_ref[pick]).astype(np.float32))
        self.t.append(((rec.stamps_ns[pick] - self.plan.first_stamp) * 1e-9).astype(np.float32))
        self.scored.append(rec.score_mask[pick])

    def rows(self, res: SequenceResult, rate: float | None, rate_hz: float, mode: str) -> list[ResultRow]:
        stats = self.run.finish() if self.run is not None else [RunStats() for _ in self.specs]
        label = self.condition.label
        if self.transforms:
            res.perturbations.setdefault(label, {})[self.plan.scenario] = [
                {"perturbation": p.text(), **tr.info()} for p, tr in zip(self.condition.parts, self.transforms,
                                                                         strict=True)
            ]
        return [
            ResultRow(sequence=res.name, dataset=res.dataset, source=res.source, scenario=self.plan.scenario,
                      rate=NATIVE if rate is None else float(rate), rate_hz=rate_hz, resampled=rate is not None,
                      estimator=spec.label, estimator_name=spec.name, mode=RECORDED if spec.name == RECORDED else mode,
                      score=self._score(j, spec, acc, st.mag_samples > 0), stats=st, perturbation=label,
                      sensors="9D" if st.mag_samples > 0 else "6D")
            for j, (spec, acc, st) in enumerate(zip(self.specs, self.acc, stats, strict=True))
        ]

    def _score(self, j: int, spec: EstimatorSpec, acc: Accumulator, nine_d: bool) -> Score:
        try:
            score = acc.result(acc.with_heading or nine_d)
            off = self.offsets.result(j) if self.offsets is not None else None
            if off is not None:
                score.best_t_offset_s, score.best_t_offset_rmse_deg = off.offset_s, off.rmse_deg
                score.t_offset_step_s = off.step_s
            return score
        except EvalError as exc:
            if spec.name != RECORDED or acc.n_scored:
                raise
            what = (f"estimate file {dict(spec.params)['file']} ({spec.label})" if "file" in dict(spec.params) else
                    f"recorded estimate {spec.label}")
            raise EvalError(f"{what}: no estimate near any scored sample (within half the --max-gap, or between two "
                            "estimates at most --max-gap apart); compare its stamps with the IMU's (--t-offset adds "
                            "seconds to the estimate stamps; a file's time unit: --estimate-time-unit)") from exc

    def keep_series(self, res: SequenceResult) -> None:
        """The plot series of this run in ``res.series["conditions"][condition]`` (``curves``, ``t``, ``scored``,
        ``attitude``, each per scenario); the first condition's are also ``res.series``'s own."""
        if res.series is None:
            res.series = {"sequence": res.name, "conditions": {}}
        cond = res.series["conditions"].setdefault(self.condition.label, {})
        scn = self.plan.scenario
        cond.setdefault("curves", {})[scn] = {
            spec.label: np.concatenate(c) if c else np.zeros(0, np.float32)
            for spec, c in zip(self.specs, self.curves, strict=True)
        }
        cond.setdefault("t", {})[scn] = np.concatenate(self.t) if self.t else np.zeros(0, np.float32)
        cond.setdefault("scored", {})[scn] = np.concatenate(self.scored) if self.scored else np.zeros(0, bool)

        def cat(parts: list[NDArray[np.float32]]) -> NDArray[np.float32]:
            return np.concatenate(parts) if parts else np.zeros((0, 2), np.float32)

        # roll and pitch (°, (n, 2)) of the reference and of every estimator: the evo_traj-style plot
        cond.setdefault("attitude", {})[scn] = {
            REFERENCE: cat(self.att_ref), **{spec.label: cat(a) for spec, a in zip(self.specs, self.att, strict=True)}
        }
        first = next(iter(res.series["conditions"].values()))
        res.series.update(first)

    def keep_estimates(self, res: SequenceResult) -> None:
        parts = self.estimates or []
        stamps = np.concatenate([p[0] for p in parts]) if parts else np.zeros(0, np.int64)
        quats = {  # the runner's (recorded ones are in the bag already)
            spec.label: np.concatenate([p[1][j] for p in parts]) if parts else np.zeros((0, 4))
            for j, spec in enumerate(self.own)
        }
        res.estimates = {"scenario": self.plan.scenario, "stamps": stamps, "quats": quats}


def _plan_runs(summary: Summary, settings: EvalSettings, name: str, native: bool,
               recorded: list[EstimatorSpec]) -> list[_ScenarioRun]:
    """One run per condition × scenario (series for the conditions to plot, estimates for the very first run). The
    time offset is searched in one scenario per condition: as-recorded when evaluated (the stamps as they are),
    else the first (the paper's scenarios do not change the stamps)."""
    want_series = native and settings.series_for is not None and settings.series_for in ("*", "all", name)
    plotted = settings.series_conditions
    offset_scenario = AS_RECORDED if AS_RECORDED in settings.scenarios else settings.scenarios[0]
    runs = []
    for c, condition in enumerate(settings.conditions):
        for s, scn in enumerate(settings.scenarios):
            slot = c * len(settings.scenarios) + s
            # recorded estimates exist for the recording as it is only: as-recorded, unperturbed, own rate
            served = recorded if native and scn == AS_RECORDED and not condition.parts else []
            runs.append(_ScenarioRun(ScenarioPlan(scn, summary, settings.seed), condition, slot, settings, name,
                                     want_series and (plotted is None or condition.label in plotted),
                                     native and settings.keep_estimates and slot == 0,
                                     served, offsets=scn == offset_scenario))
    return [r for r in runs if r.specs]


def _summarise(src: Source, rate: float | None, settings: EvalSettings, res: SequenceResult,
               native_rest: Rest | None = None) -> Summary:
    """The first pass; names the result and warns when a scenario would remove a bias but there is no rest.
    ``native_rest``: the rest detected at the recording's own rate, used for the resampled ones."""
    summary = summarise(src, settings.rest if settings.rest is not None or rate is None else native_rest)
    if not res.name:
        res.name, res.dataset, res.citation = summary.name, summary.dataset, summary.citation
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
    for group in [runs] if runner.interleaved else [[r] for r in runs]:
        for run in group:
            run.begin(runner)
        offset = 0
        for chunk in src.chunks():
            for run in group:
                run.feed(chunk, offset)
            offset += len(chunk)
        for run in group:
            res.rows.extend(run.rows(res, rate, rate_hz, runner.mode))
            if run.series:
                run.keep_series(res)
            if run.estimates is not None:
                run.keep_estimates(res)


def _warn(res: SequenceResult, text: str) -> None:
    if text not in res.warnings:
        res.warnings.append(text)


def evaluate_source(source: str | os.PathLike[str], settings: EvalSettings, runner: Runner | None = None,
                    recording: Recording | None = None) -> SequenceResult:
    """Every rate × scenario × estimator on one input; any problem ends up in ``result.error`` naming it.

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
    except EvalError as exc:
        res = SequenceResult(source=str(source), error=str(exc))
    except Exception as exc:  # an estimator crash must not take the other inputs down
        res = SequenceResult(source=str(source), error=f"{source}: {type(exc).__name__}: {exc}")
    res.seconds = time.perf_counter() - t0
    res.cpu_seconds = time.process_time() - c0
    return res


def _init_worker() -> None:
    import signal

    # Ctrl-C reaches the whole process group: the parent handles it and stops the workers
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # one core per worker: ONNX Runtime and BLAS would otherwise fight over the cores
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = "1"


def evaluate_sources(sources: Sequence[str], settings: EvalSettings, jobs: int = 1,
                     progress: Progress | None = None, runner: Runner | None = None) -> list[SequenceResult]:
    """Evaluate inputs, in ``jobs`` worker processes when > 1 (offline only); results in input order."""
    if jobs <= 1 or len(sources) <= 1 or (runner is not None and not runner.interleaved):
        results = []
        for i, src in enumerate(sources):
            results.append(evaluate_source(src, settings, runner))
            if progress:
                progress(i + 1, len(sources), results[-1])
        return results
    return _evaluate_parallel(sources, settings, jobs, progress)


def _evaluate_parallel(sources: Sequence[str], settings: EvalSettings, jobs: int,
                       progress: Progress | None) -> list[SequenceResult]:
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor, as_completed

    results: list[SequenceResult | None] = [None] * len(sources)
    ctx = mp.get_context("spawn" if os.name == "nt" else "forkserver")
    pool = ProcessPoolExecutor(max_workers=jobs, mp_context=ctx, initializer=_init_worker)
    try:
        futures = {pool.submit(evaluate_source, src, settings): i for i, src in enumerate(sources)}
        for done, fut in enumerate(as_completed(futures), 1):
            i = futures[fut]
            try:
                results[i] = r = fut.result()
            except Exception as exc:  # a worker died
                results[i] = r = SequenceResult(source=str(sources[i]), error=f"{sources[i]}: worker failed: {exc}")
            if progress:
                progress(done, len(sources), r)
    except BaseException:
        # Ctrl-C (or any error here): stop the workers now instead of waiting for their sequences
        procs = list(getattr(pool, "_processes", {}).values())
        pool.shutdown(wait=False, cancel_futures=True)
        for p in procs:
            if p.is_alive():
                p.terminate()
        for p in procs:
            p.join(5)
        raise
    pool.shutdown(wait=True)
    return [r for r in results if r is not None]
