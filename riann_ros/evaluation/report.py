"""What ``riann-bag-eval`` shows and writes: the summary table and one run's content (ROS-free).

:class:`Report` holds one run (settings, per-input results, tuning) and what results.json holds of it; the files
(results.csv, results.json, report.md, figures) are :mod:`~riann_ros.evaluation.report_files`.
"""

from __future__ import annotations

import platform
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from riann_ros.evaluation.aggregate import Group, aggregate, rate_label
from riann_ros.evaluation.offsets import timing_notes
from riann_ros.evaluation.perturb import DEFINITIONS as PERTURB_DEFINITIONS
from riann_ros.evaluation.rest import DEFINITION as REST_DEFINITION
from riann_ros.evaluation.results import BIAS_KEYS, EvalSettings, ResultRow, SequenceResult
from riann_ros.evaluation.scenarios import BIAS_STD_DPS, DEFINITIONS
from riann_ros.evaluation.scoring import STATS, stat_field
from riann_ros.evaluation.uncertainty import KEYS as UNCERTAINTY_KEYS

CSV_FIELDS = (
    "sequence",
    "dataset",
    "scenario",
    "perturbation",
    "rate",
    "rate_hz",
    "estimator",
    "rmse_deg",
    "max_err_deg",
    "mean_err_deg",
    "median_err_deg",
    "std_err_deg",
    "min_err_deg",
    "best_t_offset_s",
    "best_t_offset_rmse_deg",
    "t_offset_step_s",
    "heading_rmse_deg",
    "heading_mean_deg",
    "heading_median_deg",
    "heading_std_deg",
    "heading_min_deg",
    "heading_max_deg",
    "total_rmse_deg",
    "total_mean_deg",
    "total_median_deg",
    "total_std_deg",
    "total_min_deg",
    "total_max_deg",
    "n_samples",
    "n_scored",
    "n_unestimated",
    "coverage",
    "seconds",
    "cpu_seconds",
    "mode",
    "published",
    "received",
    "lost",
    "source",
    *UNCERTAINTY_KEYS,
    "has_reference",
    *(stat_field("heading_drift", st) for st in STATS),
    "t_offset_ref_turn_dps",
    *BIAS_KEYS,
)
METRIC = (
    "RMSE of e_alpha = 2 acos(sqrt(w^2+z^2)) of q_ref * conj(q_est), deg, over score mask & reference present & "
    "estimate present; per sequence also the mean, median (log-spaced histogram, within 0.1 %), std (population), "
    "min and max of e_alpha (heading and total error likewise where scored); best_t_offset_s: the time added to the "
    "estimate stamps that minimises the e_alpha RMSE within +-offset_steps steps of the stream "
    "(best_t_offset_rmse_deg: the RMSE there), searched in the as-recorded scenario (else the first); "
    "t_offset_ref_turn_dps: the RMS rate at which the reference's gravity direction turns there (0.5 s apart); "
    "heading_drift_*: 6D runs with --heading, the heading error after rotating the estimate about the vertical by the "
    "heading offset at the first scored sample (heading_* and total_* are unaligned, as evo_ape without alignment); "
    "inputs without a reference (has_reference false) get no scores: sequences[].agreement holds the pairwise "
    "inclination difference of the estimators (RMS, mean, max, time of the max, the 1 s windows of largest RMS)"
)
PRINT_ROWS = 48  # per-sequence tables longer than this are not printed (they are in report.md and results.csv)


# ---------------------------------------------------------------------------------------------------
# the summary table
# ---------------------------------------------------------------------------------------------------
def _cells(agg: Sequence[Group]) -> tuple[list[str], list[list[str]]]:
    """Headers and cells of the summary table: perturbation and rate columns only when they vary."""
    prt = len({a.perturbation for a in agg}) > 1
    multi = len({a.rate for a in agg}) > 1
    headers = ["scenario", *(["perturbation"] if prt else []), "dataset", *(["rate"] if multi else []), "estimator",
               "n", "mean", "median", "max"]
    rows = [
        [a.scenario, *([a.perturbation] if prt else []), a.dataset, *([rate_label(a.rate)] if multi else []),
         a.estimator, str(a.n), f"{a.mean:.2f}", f"{a.median:.2f}", f"{a.max:.2f}"]
        for a in agg
    ]
    return headers, rows


def format_table(agg: Sequence[Group], title: str = "attitude RMSE e_α (°) per sequence") -> str:
    """Estimator × scenario × dataset (× perturbation, × rate when several): n, mean / median / max RMSE."""
    if not agg:
        return "(no results)"
    headers, lines = _cells(agg)
    widths = [max(len(h), *(len(r[i]) for r in lines)) for i, h in enumerate(headers)]
    numeric = {"n", "mean", "median", "max", "rate"}

    def fmt(row: list[str]) -> str:
        return "  ".join(
            c.rjust(w) if h in numeric else c.ljust(w) for c, w, h in zip(row, widths, headers, strict=True)
        )

    out = [title, fmt(headers), "  ".join("-" * w for w in widths)]
    prev = None
    for row, a in zip(lines, agg, strict=True):
        key = (a.scenario, a.perturbation, a.dataset, a.rate)
        if prev is not None and key != prev:
            out.append("")
        prev = key
        out.append(fmt(row))
    return "\n".join(out)


def format_markdown_table(agg: Sequence[Group]) -> str:
    headers, rows = _cells(agg)
    units = {"mean": "mean °", "median": "median °", "max": "max °", "rate": "rate Hz"}
    numeric = {"n", "mean", "median", "max", "rate"}
    out = ["| " + " | ".join(units.get(h, h) for h in headers) + " |",
           "|" + "".join("---:|" if h in numeric else "---|" for h in headers)]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(out)


# ---------------------------------------------------------------------------------------------------
# one run
# ---------------------------------------------------------------------------------------------------
@dataclass
class Report:
    """One ``riann-bag-eval`` run: what was asked, what came out."""

    command: str
    sources: list[str]
    settings: EvalSettings
    results: list[SequenceResult]
    elapsed_s: float = 0.0
    jobs: int = 1
    tuning: list[dict[str, Any]] = field(default_factory=list)

    @property
    def rows(self) -> list[ResultRow]:
        return [row for r in self.results if not r.error for row in r.rows]

    @property
    def failures(self) -> list[dict[str, str]]:
        return [{"source": r.source, "error": r.error} for r in self.results if r.error]

    @property
    def summary(self) -> list[Group]:
        return aggregate(self.rows)

    @property
    def timing_notes(self) -> list[str]:
        """What the best time offsets say (:func:`~riann_ros.evaluation.offsets.timing_notes`)."""
        return timing_notes(self.rows, self.settings.offset_steps)

    def settings_dict(self) -> dict[str, Any]:
        s = self.settings
        return {
            "command": self.command,
            "inputs": self.sources,
            "estimators": [e.to_dict() for e in s.estimators],
            "scenarios": s.scenarios,
            "seed": s.seed,
            "rates": s.rates,
            "perturbations": [c.label for c in s.conditions],
            "jobs": self.jobs,
            "bias_std_dps": BIAS_STD_DPS,
            "scenario_definition": {k: v for k, v in DEFINITIONS.items() if k in s.scenarios},
            "rest": None if s.rest is None else list(s.rest),
            "rest_definition": REST_DEFINITION,
            "offset_steps": s.offset_steps,
            "score_from_s": s.score_from_s,
            "reference_sd_deg": s.reference_sd_deg,
            "perturbation_definition": PERTURB_DEFINITIONS,
            "metric": METRIC,
            "input_warnings": s.input_warnings,
        }

    def payload(self) -> dict[str, Any]:
        """The content of results.json."""
        return {
            "settings": self.settings_dict(),
            "versions": versions(),
            "elapsed_s": self.elapsed_s,
            "summary": [g.to_dict() for g in self.summary],
            "sequences": [
                {"source": r.source, "name": r.name, "dataset": r.dataset, "seconds": r.seconds,
                 "cpu_seconds": r.cpu_seconds, "scenarios": r.scenarios, "perturbations": r.perturbations,
                 "warnings": r.warnings, **({"salvaged": r.salvaged} if r.salvaged else {}),
                 "has_reference": r.has_reference, **({"recorded_name": r.recorded_name} if r.recorded_name else {}),
                 "health": r.health, **({} if r.has_reference else {"agreement": r.agreement})}
                for r in self.results
                if not r.error
            ],
            "results": [row.to_dict() for row in self.rows],
            "timing_notes": self.timing_notes,
            "tuning": self.tuning,
            "failures": self.failures,
        }


def versions() -> dict[str, Any]:
    """Package, model and runtime versions for results.json."""
    out: dict[str, Any] = {"python": platform.python_version(), "platform": platform.platform()}
    from importlib import metadata

    for dist in ("riann_ros", "riann", "onnxruntime", "numpy", "scipy", "vqf"):
        try:
            out[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            out[dist] = None
    if out["riann_ros"] is None:
        from riann_ros import __version__

        out["riann_ros"] = __version__
    try:
        import hashlib

        from riann_ros.estimators.riann import default_model_path

        p = default_model_path()
        out["riann_model"] = {"path": str(p), "sha256": hashlib.sha256(p.read_bytes()).hexdigest()}
    except Exception as exc:
        out["riann_model"] = {"error": str(exc)}
    return out
