"""One condition × scenario of one sequence at one rate, as the pipeline runs it (ROS-free; see
:mod:`~riann_ros.evaluation.run`): the scenario plan, the condition's transforms, the runner's run, one
:class:`~riann_ros.evaluation.scoring.Accumulator` per estimator, the offset search, the plot series and the
estimates kept for ``--write-estimates``. On an input without a reference it scores nothing and keeps instead the
estimators' pairwise agreement (:mod:`~riann_ros.evaluation.agreement`) and their roll, pitch and heading with the
σ they report, for the overlay figure."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from riann_ros.evaluation.agreement import Agreement
from riann_ros.evaluation.errors import EvalError
from riann_ros.evaluation.offsets import OffsetSearch
from riann_ros.evaluation.perturb import Condition, Transform
from riann_ros.evaluation.results import (
    NATIVE,
    RECORDED,
    REFERENCE,
    SERIES_POINTS,
    EvalSettings,
    ResultRow,
    RunStats,
    SequenceResult,
)
from riann_ros.evaluation.runners import Joined, RecordedRunner, Run, Runner, run_sigmas
from riann_ros.evaluation.scenarios import ScenarioPlan, sequence_seed
from riann_ros.evaluation.scoring import Accumulator, Score, error_deg, heading_deg, roll_pitch_deg
from riann_ros.evaluation.specs import EstimatorSpec
from riann_ros.gate import GateConfig
from riann_ros.recording import Recording

F32 = NDArray[np.float32]


class ScenarioRun:
    """One condition × scenario of one sequence at one rate: the scenario plan, the condition's transforms, the
    runner's run and one accumulator per estimator (``free``: the input has no reference: agreement instead)."""

    def __init__(self, plan: ScenarioPlan, condition: Condition, settings: EvalSettings, name: str,
                 series: bool, estimates: bool, recorded: list[EstimatorSpec] | None = None,
                 offsets: bool = False, free: bool = False) -> None:
        self.plan = plan
        self.condition = condition
        self.own = settings.estimators  # run by the runner
        self.recorded = recorded or []  # served from the bag
        self.specs = [*self.own, *self.recorded]
        rngs = [np.random.default_rng(sequence_seed(settings.seed, f"{name}:{condition.label}:{k}"))
                for k in range(len(condition.parts))]
        self.transforms: list[Transform] = condition.start(rngs)
        rate = plan.gate.nominal_rate
        self.gate = GateConfig.for_rate(condition.nominal_rate(rate)) if condition.parts else plan.gate
        self.acc = [Accumulator(settings.with_heading, settings.reference_sd_deg) for _ in self.specs]
        self.score_from_ns = plan.first_stamp + round(settings.score_from_s * 1e9)  # scored from this stamp on
        # the time offset that minimises e_α (one scenario per sequence × condition × rate: see run._plan_runs)
        self.offsets = (OffsetSearch(len(self.specs), 1.0 / self.gate.nominal_rate, settings.offset_steps)
                        if offsets and settings.offset_steps > 0 and not free else None)
        self.agreement = Agreement([s.label for s in self.specs], plan.first_stamp) if free else None
        self.run: Run | None = None
        self.what = f"{name} {plan.scenario}" + (f" {condition.label}" if condition.parts else "")  # for progress
        self.fed = 0  # samples fed so far
        length = plan.length * (condition.nominal_rate(rate) / rate if condition.parts else 1.0)
        self.step = settings.series_step if settings.series_step > 0 else max(1, -(-int(length) // SERIES_POINTS))
        self.series = series
        self.curves: list[list[F32]] = [[] for _ in self.specs]
        self.att: list[list[F32]] = [[] for _ in self.specs]
        self.sig: list[list[F32]] = [[] for _ in self.specs]  # free inputs: σ (°) of inclination and heading
        self.att_ref: list[F32] = []
        self.t: list[F32] = []
        self.scored: list[NDArray[np.bool_]] = []
        self.estimates: list[tuple[NDArray[np.int64], list[NDArray[np.float64]], NDArray[np.float64] | None,
                                   NDArray[np.bool_]]] | None = [] if estimates else None

    @property
    def free(self) -> bool:
        return self.agreement is not None

    def begin(self, runner: Runner) -> None:
        runs = [runner.start(self.own, self.gate, self.what)] if self.own else []
        runs += [RecordedRunner().start(self.recorded, self.gate)] if self.recorded else []
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
        if self.agreement is not None:
            self.agreement.add(rec.stamps_ns, qs)
        if self.series and (rec.quat_ref is not None or self.free):
            self._add_series(rec, qs, sigmas)
        if self.estimates is not None:
            self.estimates.append((rec.stamps_ns - self.plan.shift, qs, rec.quat_ref, rec.score_mask))
        self.fed += len(rec)

    def _add_series(self, rec: Recording, qs: list[NDArray[np.float64]],
                    sigmas: list[NDArray[np.float64] | None]) -> None:
        """Every ``step``-th sample (counted over the whole sequence): e_α, roll and pitch of each estimator, the
        reference's roll and pitch, time and score mask; without a reference roll, pitch, heading and σ."""
        pick = slice((-self.fed) % self.step, None, self.step)
        for j, q in enumerate(qs):
            if rec.quat_ref is not None:
                self.curves[j].append(error_deg(rec.quat_ref[pick], q[pick]).astype(np.float32))
                self.att[j].append(roll_pitch_deg(q[pick]).astype(np.float32))
                continue
            self.att[j].append(np.column_stack([roll_pitch_deg(q[pick]), heading_deg(q[pick])]).astype(np.float32))
            sig = sigmas[j]
            self.sig[j].append(np.full((len(q[pick]), 2), np.nan, np.float32) if sig is None
                               else np.degrees(sig[pick, :2]).astype(np.float32))
        if rec.quat_ref is not None:
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
        if self.agreement is not None:
            res.agreement += [{"scenario": self.plan.scenario, "perturbation": label,
                               "rate": NATIVE if rate is None else float(rate), **pair}
                              for pair in self.agreement.result()]
        return [
            ResultRow(sequence=res.name, dataset=res.dataset, source=res.source, scenario=self.plan.scenario,
                      rate=NATIVE if rate is None else float(rate), rate_hz=rate_hz, resampled=rate is not None,
                      estimator=spec.label, estimator_name=spec.name, mode=RECORDED if spec.name == RECORDED else mode,
                      score=self._score(j, spec, acc, st.mag_samples > 0), stats=st, perturbation=label,
                      sensors="9D" if st.mag_samples > 0 else "6D", has_reference=not self.free)
            for j, (spec, acc, st) in enumerate(zip(self.specs, self.acc, stats, strict=True))
        ]

    def _score(self, j: int, spec: EstimatorSpec, acc: Accumulator, nine_d: bool) -> Score:
        if self.free:  # nothing to score against: the samples and those without an estimate only
            assert self.agreement is not None
            unest = acc.n - int(self.agreement.n_estimated[j])
            return Score(n_samples=acc.n, n_scored=0, n_unestimated=unest, rmse_deg=math.nan, max_err_deg=math.nan)
        try:
            score = acc.result(acc.with_heading or nine_d, drift=not nine_d)
            off = self.offsets.result(j) if self.offsets is not None else None
            if off is not None:
                score.best_t_offset_s, score.best_t_offset_rmse_deg = off.offset_s, off.rmse_deg
                score.t_offset_step_s, score.t_offset_ref_turn_dps = off.step_s, off.ref_turn_dps
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
        ``attitude``, each per scenario); the first condition's are also ``res.series``'s own. Without a reference:
        ``res.attitude_series["conditions"][condition]`` (``t``, ``attitude`` (n, 3) and ``sigma`` (n, 2) per
        estimator)."""
        if self.free:
            self._keep_free_series(res)
            return
        if res.series is None:
            res.series = {"sequence": res.name, "conditions": {}}
        cond = res.series["conditions"].setdefault(self.condition.label, {})
        scn = self.plan.scenario
        cond.setdefault("curves", {})[scn] = {spec.label: _cat(c, 0) for spec, c in zip(self.specs, self.curves,
                                                                                          strict=True)}
        cond.setdefault("t", {})[scn] = _cat(self.t, 0)
        cond.setdefault("scored", {})[scn] = np.concatenate(self.scored) if self.scored else np.zeros(0, bool)
        # roll and pitch (°, (n, 2)) of the reference and of every estimator: the evo_traj-style plot
        cond.setdefault("attitude", {})[scn] = {
            REFERENCE: _cat(self.att_ref, 2), **{spec.label: _cat(a, 2) for spec, a in zip(self.specs, self.att,
                                                                                            strict=True)}
        }
        first = next(iter(res.series["conditions"].values()))
        res.series.update(first)

    def _keep_free_series(self, res: SequenceResult) -> None:
        if res.attitude_series is None:
            res.attitude_series = {"sequence": res.name, "scenario": self.plan.scenario, "conditions": {}}
        res.attitude_series["conditions"][self.condition.label] = {
            "t": _cat(self.t, 0),
            "attitude": {spec.label: _cat(a, 3) for spec, a in zip(self.specs, self.att, strict=True)},
            "sigma": {spec.label: _cat(s, 2) for spec, s in zip(self.specs, self.sig, strict=True)},
        }

    def keep_estimates(self, res: SequenceResult) -> None:
        """The runner's estimates of this run (recorded ones are in the bag already), with the reference and the
        score mask at their stamps, in ``res.estimates``."""
        parts = self.estimates or []
        stamps = np.concatenate([p[0] for p in parts]) if parts else np.zeros(0, np.int64)
        quats = {spec.label: np.concatenate([p[1][j] for p in parts]) if parts else np.zeros((0, 4))
                 for j, spec in enumerate(self.own)}
        refs = [p[2] for p in parts if p[2] is not None]
        reference: NDArray[np.float64] | None = np.concatenate(refs) if refs and len(refs) == len(parts) else None
        scored = np.concatenate([p[3] for p in parts]) if parts else np.zeros(0, bool)
        res.estimates = {"scenario": self.plan.scenario, "stamps": stamps, "quats": quats, "reference": reference,
                         "scored": scored}


def _cat(parts: list[F32], width: int) -> F32:
    """The pieces of a series as one array ((0,) or (0, width) when there are none)."""
    if parts:
        return np.concatenate(parts)
    return np.zeros((0, width) if width else 0, np.float32)
