"""Offline attitude evaluation, the paper's way (ROS-free core of ``riann-bag-eval``).

One pipeline (:mod:`~riann_ros.evaluation.run`): a source yields recording chunks, with estimates recorded in the
bag aligned onto them (:mod:`~riann_ros.evaluation.sources`) → its first pass finds the motion onset and the initial
rest (:mod:`~riann_ros.evaluation.first_pass`, :mod:`~riann_ros.evaluation.rest`) → each scenario transforms the
chunks (:mod:`~riann_ros.evaluation.scenarios`) → a runner gives the estimates (in-process through the node's
``EstimatorStream``, live over DDS, or recorded in the bag) → one accumulator per scenario × estimator scores them
(:mod:`~riann_ros.evaluation.scoring`). The runners: :mod:`~riann_ros.evaluation.runners`; settings and result rows:
:mod:`~riann_ros.evaluation.results`. Estimator specs and tuning grids: :mod:`~riann_ros.evaluation.specs`;
statistics across sequences and tuning: :mod:`~riann_ros.evaluation.aggregate`; tables and files:
:mod:`~riann_ros.evaluation.report`; figures: :mod:`~riann_ros.evaluation.plots`; the ``--out`` folder policy:
:mod:`~riann_ros.evaluation.outdir`; two saved runs side by side: :mod:`~riann_ros.evaluation.compare` (report and
compare use plots and outdir; neither plots nor outdir imports them). Where the inputs run (this process, ``--jobs``,
a Dask cluster): :mod:`~riann_ros.evaluation.executors`; each finished input kept for ``--resume``:
:mod:`~riann_ros.evaluation.store`; the pass over the inputs with both: :mod:`~riann_ros.evaluation.fleet`; its
progress bar: :mod:`riann_ros.cli.progress`.
Reference: docs/evaluation.md.
"""

from riann_ros.evaluation.aggregate import ALL_DATASETS, Group, aggregate, best_of, rate_order, tune
from riann_ros.evaluation.errors import EvalError
from riann_ros.evaluation.first_pass import load_recording, summarise
from riann_ros.evaluation.input_hints import BROAD_SUFFIXES, input_hint
from riann_ros.evaluation.offsets import STEPS as OFFSET_STEPS
from riann_ros.evaluation.offsets import timing_notes
from riann_ros.evaluation.perturb import Condition, parse_condition, parse_perturbation
from riann_ros.evaluation.rest import NO_REST_WARNING, Rest, parse_rest
from riann_ros.evaluation.results import (
    NATIVE,
    RECORDED,
    EvalSettings,
    ResultRow,
    RunStats,
    SequenceResult,
    recorded_spec,
)
from riann_ros.evaluation.run import evaluate_source, evaluate_sources
from riann_ros.evaluation.runners import OfflineRunner, RecordedRunner
from riann_ros.evaluation.scenarios import (
    AS_RECORDED,
    BIAS_STD_DPS,
    PAPER_SCENARIOS,
    PARTIAL,
    REALISTIC,
    RESTRICTIVE,
    SCENARIOS,
    ScenarioInfo,
    ScenarioPlan,
    parse_scenarios,
    random_bias,
    scenario_recording,
    sequence_seed,
)
from riann_ros.evaluation.scoring import ERRORS, STATS, Accumulator, ErrorStats, Score, score, stat_field
from riann_ros.evaluation.sources import BagTopics, Chunk, EstimateFile, Source, open_source
from riann_ros.evaluation.specs import (
    EstimatorSpec,
    available_estimators,
    grid_specs,
    make_label,
    parse_estimator,
    parse_estimators,
    parse_grid,
)

__all__ = [
    "ALL_DATASETS",
    "AS_RECORDED",
    "BIAS_STD_DPS",
    "BROAD_SUFFIXES",
    "ERRORS",
    "NATIVE",
    "NO_REST_WARNING",
    "OFFSET_STEPS",
    "PAPER_SCENARIOS",
    "PARTIAL",
    "REALISTIC",
    "RECORDED",
    "RESTRICTIVE",
    "SCENARIOS",
    "STATS",
    "Accumulator",
    "BagTopics",
    "Chunk",
    "Condition",
    "ErrorStats",
    "EstimateFile",
    "EstimatorSpec",
    "EvalError",
    "EvalSettings",
    "Group",
    "OfflineRunner",
    "RecordedRunner",
    "Rest",
    "ResultRow",
    "RunStats",
    "ScenarioInfo",
    "ScenarioPlan",
    "Score",
    "SequenceResult",
    "Source",
    "aggregate",
    "available_estimators",
    "best_of",
    "evaluate_source",
    "evaluate_sources",
    "grid_specs",
    "input_hint",
    "load_recording",
    "make_label",
    "open_source",
    "parse_condition",
    "parse_estimator",
    "parse_estimators",
    "parse_grid",
    "parse_perturbation",
    "parse_rest",
    "parse_scenarios",
    "random_bias",
    "rate_order",
    "recorded_spec",
    "scenario_recording",
    "score",
    "sequence_seed",
    "stat_field",
    "summarise",
    "timing_notes",
    "tune",
]
