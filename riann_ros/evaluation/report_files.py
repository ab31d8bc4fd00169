"""``riann-bag-eval``'s result files in ``--out`` (ROS-free): results.csv, results.json, report.md and the figures of a
:class:`~riann_ros.evaluation.report.Report`. :func:`write_results` writes them, removing what it wrote if stopped
half-way, so a folder never holds half a run; a figure that cannot be drawn costs only itself."""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from riann_ros.evaluation import coverage
from riann_ros.evaluation import free_report as fr
from riann_ros.evaluation import plots as pl
from riann_ros.evaluation.aggregate import scenario_order
from riann_ros.evaluation.outdir import prepare_out, previous_results
from riann_ros.evaluation.plots_free import plot_attitude_overlay
from riann_ros.evaluation.report import CSV_FIELDS, Report, format_markdown_table
from riann_ros.evaluation.results import ResultRow
from riann_ros.evaluation.scoring import ERRORS
from riann_ros.evaluation.seq_tables import (
    ERROR_TITLES,
    format_heading_table,
    format_stats_table,
    per_sequence_markdown,
)
from riann_ros.evaluation.uncertainty_report import NOTE as UNCERTAINTY_NOTE
from riann_ros.evaluation.uncertainty_report import format_uncertainty_table, plot_error_vs_sigma, reference_line


def write_csv(path: Path, rows: Sequence[ResultRow]) -> None:
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(CSV_FIELDS), extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6f}" if isinstance(v, float) else v) for k, v in r.to_dict().items()})


def _clean(obj: Any) -> Any:
    """JSON-safe: NaN/inf → None, numpy scalars → Python."""
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_clean(v) for v in obj]
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def write_json(path: Path, payload: dict[str, Any]) -> None:
    with open(path, "w") as f:
        json.dump(_clean(payload), f, indent=1)
        f.write("\n")


def _timing_and_statistics(report: Report) -> list[str]:
    """report.md's timing notes, per-sequence RMSE tables and per-sequence error statistics."""
    notes = report.timing_notes
    lines = ["## Timing", ""] + [f"- {n}" for n in notes] + [""] if notes else []
    per_sequence = per_sequence_markdown(report.rows)
    lines += ["## Per sequence", "", *per_sequence] if per_sequence else []
    for err in ERRORS:
        table = format_stats_table(report.rows, err, markdown_table=True)
        if table:
            lines += [f"### Error statistics: {ERROR_TITLES[err]}", "", table, ""]
    return lines


def _free_sections(report: Report) -> list[str]:
    """report.md's sections on the inputs without a reference (agreement, bias) and every input's stream health."""
    lines = []
    agreement = fr.format_agreement(report.results, markdown_table=True)
    if agreement:
        bias = fr.format_bias(report.results, report.rows, markdown_table=True)
        lines += ["## Without a reference", "", fr.NOTE, "", agreement, "", *([bias, ""] if bias else [])]
    health = fr.format_health(report.results, markdown_table=True, every=True)
    return lines + (["## Stream health", "", health, ""] if health else [])


def _head(report: Report) -> list[str]:
    """report.md's title, command, what ran (the scenarios that did: an input without a reference runs as recorded
    only), the metric when anything is scored, the data's citations and which inputs have a reference."""
    s = report.settings
    rates = ", ".join("native" if r is None else f"{r:g} Hz" for r in s.rates)
    ran = scenario_order(r.scenario for r in report.rows) or s.scenarios
    scored = any(r.has_reference for r in report.rows)
    lines = ["# riann-bag-eval report", "", f"Command: `{report.command}`", "",
             f"Scenarios: {', '.join(ran)}; seed {s.seed}; rates: {rates}; perturbations: "
             f"{', '.join(c.label for c in s.conditions)}.",
             *(["Metric: RMSE of the inclination error e_α (heading ignored, paper eq. 3) over the scored samples "
                "with a reference; table values summarise the per-sequence RMSEs."] if scored else [])]
    citations = sorted({r.citation for r in report.results if r.citation and not r.error})
    if citations:
        lines += ["", "Data: " + "; ".join(citations)]
    which = fr.which_is_which(report.results)
    return [*lines, "", *([f"Inputs {which}.", ""] if which else [])]


def markdown(report: Report, plots: Sequence[Path]) -> str:
    """The content of report.md: only the sections that have content."""
    lines = _head(report)
    if report.summary:
        recorded = coverage.recorded_lines(report.rows)
        lines += ["## Summary", "", format_markdown_table(report.summary), "",
                  *([*(f"- {x}" for x in recorded), ""] if recorded else [])]
    lines += _free_sections(report)
    nine = format_heading_table(report.rows, markdown_table=True)
    if nine:
        lines += ["## Heading (9D runs: estimators that used the magnetometer)", "",
                  "Heading and total error as BROAD defines them (error quaternion in the earth frame); the heading "
                  "of a 9D estimate is absolute (magnetic north), so it is scored as it is.", "", nine, ""]
    ref_sd = report.settings.reference_sd_deg
    unc = format_uncertainty_table(report.rows, markdown_table=True, reference_sd_deg=ref_sd)
    if unc:
        lines += [f"## Uncertainty (the σ each estimator reports; reference σ {ref_sd:g}°)", "", UNCERTAINTY_NOTE, "",
                  reference_line(ref_sd), "", unc, ""]
    if report.tuning:
        lines += ["## Tuning (grid search on these sequences)", ""]
        for t in report.tuning:
            b = t["best"]
            lines.append(
                f"- {t['estimator']} ({t['scenario']}): best {b['label']} — mean {b['mean']:.2f}°, max {b['max']:.2f}°"
            )
        lines.append("")
    warnings = [*report.settings.input_warnings, *(w for r in report.results if not r.error for w in r.warnings),
                *coverage.warnings(report.rows)]
    if warnings:
        lines += ["## Warnings", ""] + [f"- {w}" for w in warnings] + [""]
    lines += _timing_and_statistics(report)
    if report.failures:
        lines += ["## Failed inputs", ""] + [f"- {f['error']}" for f in report.failures] + [""]
    if plots:
        lines += ["## Plots", ""] + [f"![{p.stem}]({p.name})" for p in plots if p.suffix == ".png"] + [""]
    return "\n".join(lines)


def _plots(report: Report, rows: list[ResultRow], out: Path) -> list[Path]:
    """The figures: boxplots, error over time (the first sequence with series), roll/pitch per sequence (that one,
    or every sequence with ``--plot-sequence all``) and perturbation condition, the overlay of every input without a
    reference, RMSE vs rate; every condition, or those of ``--plot-perturb``."""
    chosen = report.settings.series_conditions
    free = [r.attitude_series for r in report.results if r.attitude_series and not r.error]
    rows = [r for r in rows if r.has_reference and coverage.ranked(r)]
    figures = pl.plot_boxes(rows, out, conditions=chosen)
    with_series = [r.series for r in report.results if r.series and not r.error]
    if with_series:
        figures += pl.plot_error_over_time(with_series[0], out, conditions=chosen)
    for series in with_series if report.settings.series_for == "all" else with_series[:1]:
        for cond in pl.series_conditions(series, chosen):
            figures += pl.plot_attitude(series, out, condition=cond)
    for series in free:
        for cond in pl.series_conditions(series, chosen):
            figures += plot_attitude_overlay(series, out, condition=cond)
    return figures + pl.plot_rmse_vs_rate(rows, out, conditions=chosen) + plot_error_vs_sigma(rows, out)


@dataclass
class Written:
    """What :func:`write_results` wrote: the figures, and what could not be drawn (the tables are written)."""

    figures: list[Path] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)


def write_results(out: Path, report: Report, plots: bool = True, replace: bool = False) -> Written:
    """results.csv, results.json, report.md and (``plots``) the figures in ``out``; returns the figures written and the
    problems. A figure that cannot be drawn is a problem (the tables and report.md are written all the same).

    An earlier run's result files in ``out`` are removed first with ``replace``, else
    :class:`~riann_ros.evaluation.outdir.OutputExists`
    (:func:`prepare_out`): a folder never mixes two runs. If anything else stops it half-way (Ctrl-C, a full disk),
    the files of this call are removed again."""
    prepare_out(out, replace)
    try:
        rows = report.rows
        write_csv(out / "results.csv", rows)
        write_json(out / "results.json", report.payload())
        done = Written()
        if plots and rows:
            try:
                done.figures = _plots(report, rows, out)
            except Exception as exc:  # a figure must not cost the tables
                done.problems.append(f"the plots could not be drawn ({type(exc).__name__}: {exc}); results.csv, "
                                     "results.json and report.md are written")
        (out / "report.md").write_text(markdown(report, done.figures))
        return done
    except BaseException:
        for f in previous_results(out):  # all of this call's: the earlier run's are gone
            f.unlink(missing_ok=True)
        raise
