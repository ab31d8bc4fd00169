"""Across sequences: group statistics, and tuning a filter on the inputs (ROS-free)."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

from riann_ros.evaluation.coverage import ranked
from riann_ros.evaluation.errors import EvalError
from riann_ros.evaluation.executors import Executor
from riann_ros.evaluation.perturb import NONE
from riann_ros.evaluation.results import NATIVE, EvalSettings, Progress, ResultRow
from riann_ros.evaluation.run import evaluate_sources
from riann_ros.evaluation.scenarios import SCENARIOS
from riann_ros.evaluation.specs import EstimatorSpec, grid_specs, make_label, parse_grid

ALL_DATASETS = "all"


@dataclass
class Group:
    """Statistics of the per-sequence RMSEs of one estimator × scenario × perturbation × dataset × rate."""

    estimator: str
    scenario: str
    dataset: str
    rate: str | float
    n: int
    mean: float
    median: float
    max: float
    min: float
    perturbation: str = NONE

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def rate_label(rate: str | float) -> str:
    """A rate key as shown in tables: ``native`` or the rate in Hz (``50``, ``12.5``)."""
    return str(rate) if rate == NATIVE else f"{float(rate):g}"


def rate_order(rate: str | float) -> tuple[int, float]:
    """Sort key for rate keys: native first, then ascending Hz."""
    return (0, 0.0) if rate == NATIVE else (1, float(rate))


def scenario_order(scenarios: Iterable[str]) -> list[str]:
    """The scenarios present, in the evaluator's order."""
    present = set(scenarios)
    return [s for s in SCENARIOS if s in present] + sorted(present - set(SCENARIOS))


def aggregate(rows: Iterable[ResultRow], metric: str = "rmse_deg") -> list[Group]:
    """Per estimator × scenario × perturbation × dataset × rate: n, mean, median, max, min of the per-sequence
    ``metric`` (BROAD's group averaging: RMSE per trial, then the plain mean). With several datasets an ``all``
    group over every sequence is added. Rows of inputs without a reference (no scores) are left out, and recorded
    estimates that cover too little of the scored span to be ranked (:func:`~riann_ros.evaluation.coverage.ranked`)."""
    rows = [r for r in rows if r.has_reference and ranked(r) and getattr(r.score, metric) is not None]
    groups: dict[tuple[str, str, str, str, str | float], list[float]] = {}
    datasets = sorted({r.dataset for r in rows})
    for r in rows:
        for d in [r.dataset] + ([ALL_DATASETS] if len(datasets) > 1 else []):
            key = (r.estimator, r.scenario, r.perturbation, d, r.rate)
            groups.setdefault(key, []).append(float(getattr(r.score, metric)))
    order_est = list(dict.fromkeys(r.estimator for r in rows))
    order_scn = scenario_order(r.scenario for r in rows)
    order_prt = list(dict.fromkeys(r.perturbation for r in rows))
    order_ds = [*datasets, ALL_DATASETS]

    def order(kv: tuple[tuple[str, str, str, str, str | float], list[float]]) -> tuple:
        est, scn, prt, ds, rate = kv[0]
        return (order_scn.index(scn), order_prt.index(prt), order_ds.index(ds), rate_order(rate),
                order_est.index(est))

    out = []
    for (est, scn, prt, ds, rate), vals in sorted(groups.items(), key=order):
        v = np.asarray(vals)
        out.append(Group(est, scn, ds, rate, len(v), float(v.mean()), float(np.median(v)), float(v.max()),
                         float(v.min()), prt))
    return out


def best_of(rows: Iterable[ResultRow], specs: list[EstimatorSpec], scenario: str) -> dict[str, Any]:
    """The spec with the lowest mean RMSE over the sequences in ``scenario`` (all rates and perturbations
    pooled)."""
    by_label: dict[str, list[float]] = {}
    for r in rows:
        if r.scenario == scenario and r.has_reference:
            by_label.setdefault(r.estimator, []).append(r.rmse_deg)
    table: list[dict[str, Any]] = []
    for s in specs:
        v = by_label.get(s.label)
        if v:
            table.append({"label": s.label, "params": s.kwargs, "mean": float(np.mean(v)), "max": float(np.max(v))})
    if not table:
        raise EvalError("tuning produced no scores")
    table.sort(key=lambda d: float(d["mean"]))
    return {"scenario": scenario, "best": table[0], "grid": table}


def tune(text: str, sources: Sequence[str], scenario: str, seed: int, executor: Executor | None = None,
         progress: Progress | None = None, like: EvalSettings | None = None) -> tuple[dict[str, Any], EstimatorSpec]:
    """Grid-search the estimator of tuning spec ``text`` (``"madgwick"``, ``"mahony:kp=0.5/1:ki=0/0.3"``) for the
    lowest mean RMSE on ``sources`` in ``scenario``: (the grid's results, the best spec labelled ``… tuned``).
    ``like``: the evaluation's settings, whose bag topics, rest, chunk size and ``use_mag`` (6D or 9D) the tuning
    uses; ``executor``: where the grid's runs go (None: this process)."""
    name, grid = parse_grid(text)
    specs = grid_specs(name, grid)
    settings = EvalSettings(estimators=specs, scenarios=[scenario], seed=seed, offset_steps=0)  # no offset search
    if like is not None:
        settings.topics = replace(like.topics, estimates=())
        settings.rest, settings.chunk, settings.use_mag = like.rest, like.chunk, like.use_mag
    results = evaluate_sources(sources, settings, executor, progress)
    best = best_of([r for res in results if not res.error for r in res.rows], specs, scenario)
    best["estimator"] = name
    params = best["best"]["params"]
    return best, EstimatorSpec.of(name, params, f"{make_label(name, params)} tuned")
