"""What an evaluation is asked and what it gives (ROS-free): :class:`EvalSettings`, and per input a
:class:`SequenceResult` with one :class:`ResultRow` per condition × scenario × rate × estimator (the rows of
results.csv / results.json)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

from riann_ros.evaluation.offsets import STEPS as OFFSET_STEPS
from riann_ros.evaluation.perturb import NONE, Condition
from riann_ros.evaluation.scenarios import PAPER_SCENARIOS
from riann_ros.evaluation.scoring import Score
from riann_ros.evaluation.sources import STREAM_CHUNK, BagTopics, EstimateFile
from riann_ros.evaluation.specs import EstimatorSpec

NATIVE = "native"  # rate key of rows at the recording's own rate
LIVE_KEYS = ("published", "received", "lost", "unexpected")  # RunStats.live columns
RECORDED = "recorded"  # estimator name and mode of estimates recorded in a bag
SERIES_POINTS = 6000  # points per curve kept for the error-over-time and roll/pitch plots
REFERENCE = "reference"  # key of the reference's roll/pitch in a series
_SCORE_REQUIRED = ("n_samples", "n_scored", "n_unestimated", "rmse_deg", "max_err_deg")
BIAS_KEYS = ("gyro_bias_x_dps", "gyro_bias_y_dps", "gyro_bias_z_dps")  # RunStats.gyro_bias_dps columns


@dataclass
class EvalSettings:
    estimators: list[EstimatorSpec]
    scenarios: list[str] = field(default_factory=lambda: list(PAPER_SCENARIOS))
    seed: int = 0
    rates: list[float | None] = field(default_factory=lambda: [None])  # None = the recording's own rate
    conditions: list[Condition] = field(default_factory=lambda: [Condition()])  # perturbations; () = none
    with_heading: bool = False  # heading and total error also for 6D runs (heading drift); 9D runs always have them
    use_mag: str = "auto"  # as the nodes' use_mag: auto/true = 9D where the recording has a magnetometer
    series_for: str | None = None  # sequence whose series are plotted: a name, "*" (the first) or "all"
    series_step: int = 0  # keep every n-th sample of the series (0: about SERIES_POINTS points)
    series_conditions: tuple[str, ...] | None = None  # the conditions (labels) whose series are kept; None: all
    keep_estimates: bool = False  # return the estimates of the first scenario (for --write-estimates)
    chunk: int = STREAM_CHUNK  # samples per bag chunk
    rest: tuple[float, float] | None = None  # the initial rest by hand (s from the first sample); None: detect it
    topics: BagTopics = field(default_factory=BagTopics)  # which topics of the bags; recorded estimates
    offset_steps: int = OFFSET_STEPS  # search the e_α-minimising time offset within ± this many steps (0: not)
    salvage: bool = False  # score the readable part of a bag cut off by a crash (a repaired copy, bagio.repair)
    score_from_s: float = 0.0  # score every metric only from this long after the sequence's first sample (s)
    reference_sd_deg: float = 0.0  # the reference's own error per axis (1σ, °), added to σ in the uncertainty scores
    input_warnings: list[str] = field(default_factory=list)  # found while matching the inputs (estimate files)

    @property
    def recorded(self) -> list[EstimatorSpec]:
        """The estimates recorded in the bags (``topics.estimates``, labelled by their topic) and in trajectory files
        (``topics.files``, labelled by their label) as specs."""
        return self.recorded_for(None)

    def recorded_for(self, source: Path | None) -> list[EstimatorSpec]:
        """:attr:`recorded` of one input (``source``): the bags' topics and the files that belong to it."""
        return [recorded_spec(t) for t in self.topics.estimates] + [
            file_spec(f) for f in self.topics.files if source is None or f.belongs_to(source)]


@dataclass
class RunStats:
    """What a runner reports about one estimator's run besides its estimates."""

    seconds: float = 0.0  # wall time in the estimator (offline) or of the replay (live)
    cpu_seconds: float = float("nan")
    rejected: dict[str, int] = field(default_factory=dict)  # input-gate rejections per reason
    resets: dict[str, int] = field(default_factory=dict)  # estimator restarts per cause
    live: dict[str, int] | None = None  # live replays: published, received, lost, unexpected
    mag_samples: int = 0  # samples the estimator got with a magnetic field (> 0: a 9D run)
    # s after the run's first sample its online magnetometer calibration was first called calibrated (None: never,
    # or it calibrates none; NaN in results.csv)
    mag_converged_after_s: float | None = None
    gyro_bias_dps: list[float] | None = None  # the estimator's gyro-bias estimate at the end (None: it reports none)
    #: per monitor of the stream (riann_ros.monitors), how often it tripped (went from OK to WARN or ERROR)
    monitor_trips: dict[str, int] = field(default_factory=dict)


@dataclass
class ResultRow:
    """One estimator on one sequence in one scenario at one rate."""

    sequence: str
    dataset: str
    source: str
    scenario: str
    rate: str | float  # NATIVE or the resampled rate (Hz)
    rate_hz: float
    resampled: bool
    estimator: str  # label
    estimator_name: str
    mode: str
    score: Score
    sensors: str = "6D"  # 9D: the estimator used the magnetometer (its heading is scored as absolute)
    perturbation: str = NONE  # the condition's label
    stats: RunStats = field(default_factory=RunStats)
    has_reference: bool = True  # False: the input has no reference (no scores; see SequenceResult.agreement)

    @property
    def rmse_deg(self) -> float:
        """The inclination RMSE (the metric everything ranks by)."""
        return self.score.rmse_deg

    @property
    def coverage(self) -> float | None:
        """The share of the scored span (score mask, reference present) the estimate covers; None without a
        reference (:mod:`~riann_ros.evaluation.coverage`)."""
        span = self.score.n_scored + self.score.n_unestimated
        return self.score.n_scored / span if self.has_reference and span > 0 else None

    def to_dict(self) -> dict[str, Any]:
        """The flat row of results.csv / results.json."""
        d: dict[str, Any] = {
            k: getattr(self, k)
            for k in ("sequence", "dataset", "source", "scenario", "perturbation", "rate", "rate_hz", "resampled",
                      "estimator", "estimator_name", "mode", "sensors")
        }
        d["seconds"] = self.stats.seconds
        d.update((k, v) for k, v in asdict(self.score).items() if v is not None)
        d.update({f"rejected_{k}": v for k, v in self.stats.rejected.items()})
        d.update({f"reset_{k}": v for k, v in self.stats.resets.items()})
        d.update({f"trips_{k.replace(' ', '_')}": v for k, v in self.stats.monitor_trips.items()})
        d.update(self.stats.live or {})
        d["cpu_seconds"] = self.stats.cpu_seconds
        if self.sensors == "9D":
            d["mag_converged_after_s"] = self.stats.mag_converged_after_s
        d["has_reference"] = self.has_reference
        d["coverage"] = self.coverage
        if self.stats.gyro_bias_dps is not None:
            d.update(zip(BIAS_KEYS, self.stats.gyro_bias_dps, strict=True))
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ResultRow:
        """A row back from :meth:`to_dict` (a row of results.json, where NaN is null); KeyError names a missing
        column."""
        def num(v: Any) -> float:
            return float("nan") if v is None else float(v)

        # columns added later (error statistics, time offset) are None in older files
        optional: dict[str, Any] = {f.name: None if d.get(f.name) is None else float(d[f.name])
                                    for f in fields(Score) if f.name not in (*_SCORE_REQUIRED, "sigma_hist")}
        for k in ("n_yaw_mag", "n_yaw_held"):
            optional[k] = None if optional[k] is None else int(optional[k])
        score = Score(n_samples=int(d["n_samples"]), n_scored=int(d["n_scored"]),
                      n_unestimated=int(d["n_unestimated"]), rmse_deg=num(d["rmse_deg"]),
                      max_err_deg=num(d["max_err_deg"]), **optional,
                      sigma_hist=d.get("sigma_hist"))
        live = {k: int(d[k]) for k in LIVE_KEYS if k in d}
        stats = RunStats(seconds=num(d.get("seconds", 0.0)), cpu_seconds=num(d.get("cpu_seconds")),
                         rejected={k[len("rejected_"):]: int(v) for k, v in d.items() if k.startswith("rejected_")},
                         resets={k[len("reset_"):]: int(v) for k, v in d.items() if k.startswith("reset_")},
                         monitor_trips={k[len("trips_"):].replace("_", " "): int(v) for k, v in d.items()
                                        if k.startswith("trips_")},
                         live=live or None,
                         gyro_bias_dps=[float(d[k]) for k in BIAS_KEYS] if all(d.get(k) is not None for k in BIAS_KEYS)
                         else None)
        rate = d["rate"]
        return cls(sequence=str(d["sequence"]), dataset=str(d["dataset"]), source=str(d.get("source", "")),
                   scenario=str(d["scenario"]), rate=rate if rate == NATIVE else float(rate),
                   rate_hz=num(d["rate_hz"]), resampled=bool(d["resampled"]), estimator=str(d["estimator"]),
                   estimator_name=str(d.get("estimator_name", d["estimator"])), mode=str(d.get("mode", "")),
                   score=score, perturbation=str(d.get("perturbation", NONE)), stats=stats,
                   sensors=str(d.get("sensors", "6D")), has_reference=bool(d.get("has_reference", True)))


@dataclass
class SequenceResult:
    source: str
    name: str = ""
    dataset: str = ""
    error: str | None = None
    rows: list[ResultRow] = field(default_factory=list)
    scenarios: dict[str, Any] = field(default_factory=dict)  # scenario → ScenarioInfo dict
    perturbations: dict[str, Any] = field(default_factory=dict)  # condition → scenario → what each part did
    series: dict[str, Any] | None = None
    # first scenario: {"scenario", "stamps", "quats": {label: (N, 4)}, "reference": (N, 4) or None, "scored": (N,)}
    estimates: dict[str, Any] | None = None
    seconds: float = 0.0
    cpu_seconds: float = 0.0  # reading + scenarios + runs + scoring, in the worker
    citation: str = ""
    warnings: list[str] = field(default_factory=list)  # "<sequence>: <what>", for stderr and results.json
    salvaged: dict[str, Any] | None = None  # a cut-off bag scored as far as readable (--salvage): what was read
    has_reference: bool = True  # False: no reference orientation; its rows carry no scores, agreement instead
    recorded_name: str = ""  # the name the recording gives itself, when the result is named otherwise (names.py)
    health: dict[str, Any] | None = None  # the stream's own health (health.StreamHealth), native rate
    # reference-free inputs: pairwise agreement per scenario × condition × rate (agreement.Agreement rows with
    # "scenario", "perturbation", "rate"), and the roll/pitch/heading series per condition for the overlay figure
    agreement: list[dict[str, Any]] = field(default_factory=list)
    attitude_series: dict[str, Any] | None = None


def recorded_spec(topic: str) -> EstimatorSpec:
    """The spec of an estimate recorded on ``topic``: labelled by the topic, served by :class:`RecordedRunner`."""
    return EstimatorSpec(RECORDED, (("topic", topic),), topic)


def file_spec(f: EstimateFile) -> EstimatorSpec:
    """The spec of an estimate in a trajectory file: labelled by its label, served like a recorded topic."""
    return EstimatorSpec(RECORDED, (("file", f.path),), f.label)


Progress = Callable[[int, int, SequenceResult], None]
