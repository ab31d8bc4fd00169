"""Per-sequence tables of ``riann-bag-eval``: evo ape's statistics of each error (with the best time offset) and
the 9D runs' heading and total errors, as text or markdown (ROS-free; used by :mod:`~riann_ros.evaluation.report`
and the CLI)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from riann_ros.evaluation.aggregate import rate_label, rate_order, scenario_order
from riann_ros.evaluation.coverage import ranked
from riann_ros.evaluation.perturb import NONE
from riann_ros.evaluation.results import NATIVE, ResultRow
from riann_ros.evaluation.scoring import STATS


def heading_rows(rows: Sequence[ResultRow]) -> list[list[str]]:
    """Cells of the 9D table: per estimator × scenario × perturbation × rate of the 9D runs, heading and total
    RMSE (BROAD's definitions, mean / max over the sequences) beside the inclination. 6D runs never enter it:
    their heading is not referenced to anything (``--heading`` scores it, and the heading drift table shows it
    aligned at the start)."""
    nine = [r for r in rows if r.sensors == "9D" and r.score.heading_rmse_deg is not None]
    out = []
    keys = dict.fromkeys((r.estimator, r.scenario, r.perturbation, r.rate) for r in nine)
    for key in keys:
        grp = [r for r in nine if (r.estimator, r.scenario, r.perturbation, r.rate) == key]
        h = np.array([r.score.heading_rmse_deg for r in grp], dtype=float)
        t = np.array([r.score.total_rmse_deg for r in grp], dtype=float)
        i = np.array([r.rmse_deg for r in grp], dtype=float)
        out.append([key[1], key[2], rate_label(key[3]), key[0], str(len(grp)), f"{h.mean():.2f}", f"{h.max():.2f}",
                    f"{t.mean():.2f}", f"{t.max():.2f}", f"{i.mean():.2f}"])
    return out


HEADING_HEADERS = ["scenario", "perturbation", "rate", "estimator", "n", "heading mean °", "heading max °",
                   "total mean °", "total max °", "inclination mean °"]


def format_heading_table(rows: Sequence[ResultRow], markdown_table: bool = False) -> str:
    """The 9D table (empty string when no run used a magnetometer)."""
    cells = heading_rows(rows)
    if not cells:
        return ""
    if markdown_table:
        return "\n".join(["| " + " | ".join(HEADING_HEADERS) + " |", "|---|---|---:|---|" + "---:|" * 6]
                         + ["| " + " | ".join(c) + " |" for c in cells])
    return "\n".join(["9D runs (magnetometer): heading and total error RMSE (°) per sequence",
                      *aligned(HEADING_HEADERS, cells)])


def aligned(headers: Sequence[str], cells: Sequence[Sequence[str]]) -> list[str]:
    """A plain-text table: the header line and a line per row, each column left-aligned to its widest cell."""
    widths = [max(len(h), *(len(c[i]) for c in cells)) for i, h in enumerate(headers)]
    return ["  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)) for row in [headers, *cells]]


ERROR_TITLES = {"inclination": "inclination e_α", "heading": "heading", "total": "total angle",
                "heading_drift": "heading drift (6D: start heading aligned)"}


def rows_of(rows: Sequence[ResultRow], error: str) -> list[ResultRow]:
    """The rows a table of ``error`` shows: those that scored it, the heading and total error of 9D runs only (a 6D
    estimate's heading starts wherever the estimator puts it: its table is the heading drift)."""
    out = [r for r in rows if r.has_reference and r.score.stat(error, "rmse") is not None]
    return [r for r in out if r.sensors == "9D"] if error in ("heading", "total") else out


def _num(v: float | None, fmt: str = ".2f") -> str:
    return "–" if v is None or not math.isfinite(v) else format(v, fmt)


def stats_cells(rows: Sequence[ResultRow], error: str = "inclination") -> tuple[list[str], list[list[str]]]:
    """Headers and cells of a per-sequence statistics table (evo ape's rmse, mean, median, std, min, max of the
    per-sample ``error``; for the inclination also the best time offset and the RMSE there). Rows without that error
    scored are left out (:func:`rows_of`); perturbation and rate columns only when they vary."""
    rows = rows_of(rows, error)
    prt = len({r.perturbation for r in rows}) > 1
    multi = len({r.rate for r in rows}) > 1
    offsets = error == "inclination" and any(r.score.best_t_offset_s is not None for r in rows)
    headers = ["sequence", "scenario", *(["perturbation"] if prt else []), *(["rate"] if multi else []),
               "estimator", *STATS, *(["best offset ms", "rmse there"] if offsets else [])]
    cells = []
    for r in rows:
        sc = r.score
        cells.append([r.sequence, r.scenario, *([r.perturbation] if prt else []),
                      *([rate_label(r.rate)] if multi else []), r.estimator,
                      *(_num(sc.stat(error, st), ".3f" if st == "min" else ".2f") for st in STATS),
                      *([_num(None if sc.best_t_offset_s is None else sc.best_t_offset_s * 1e3, "+.1f"),
                         _num(sc.best_t_offset_rmse_deg)] if offsets else [])])
    return headers, cells


def format_stats_table(rows: Sequence[ResultRow], error: str = "inclination", markdown_table: bool = False,
                       limit: int | None = None) -> str:
    """The per-sequence statistics of ``error`` as text (or a markdown table); empty when no row has them. With
    ``limit``, a table longer than that is replaced by a line saying where it is."""
    headers, cells = stats_cells(rows, error)
    if not cells:
        return ""
    title = f"{ERROR_TITLES[error]} error (°) per sequence: rmse, mean, median, std, min, max over its scored samples"
    if error == "inclination" and "best offset ms" in headers:
        title += "; the time offset added to the estimate stamps that minimises the RMSE, and the RMSE there"
    if limit is not None and len(cells) > limit:
        return f"{title}: {len(cells)} rows, in report.md and results.csv"
    numeric = {*STATS, "best offset ms", "rmse there", "rate"}
    if markdown_table:
        return "\n".join([title + ":", "", "| " + " | ".join(headers) + " |",
                          "|" + "".join("---:|" if h in numeric else "---|" for h in headers)]
                         + ["| " + " | ".join(c) + " |" for c in cells])
    widths = [max(len(h), *(len(c[i]) for c in cells)) for i, h in enumerate(headers)]
    lines = [title, "  ".join(h.rjust(w) if h in numeric else h.ljust(w) for h, w in zip(headers, widths,
                                                                                          strict=True)),
             "  ".join("-" * w for w in widths)]
    lines += ["  ".join(c.rjust(w) if h in numeric else c.ljust(w) for c, w, h in zip(row, widths, headers,
                                                                                       strict=True))
              for row in cells]
    return "\n".join(lines)


def per_sequence_markdown(rows: Sequence[ResultRow]) -> list[str]:
    """report.md's per-sequence RMSE tables: a table per scenario × perturbation × rate, a column per estimator."""
    lines: list[str] = []
    rows = [r for r in rows if r.has_reference]
    ests = list(dict.fromkeys(r.estimator for r in rows))
    rmse = {(r.sequence, r.scenario, r.perturbation, r.estimator, r.rate): _cell(r) for r in rows}
    tables = dict.fromkeys((r.scenario, r.perturbation, r.rate) for r in rows)
    order = scenario_order(r.scenario for r in rows)
    for scn, prt, rate in sorted(tables, key=lambda k: (order.index(k[0]), rate_order(k[2]))):
        unit = "" if rate == NATIVE else " Hz"
        title = f"### {scn}, {rate_label(rate)}{unit}" + ("" if prt == NONE else f", {prt}")
        lines += [title, "", "| sequence | " + " | ".join(ests) + " |", "|---|" + "---:|" * len(ests)]
        for seq in dict.fromkeys(r.sequence for r in rows if (r.scenario, r.perturbation, r.rate) == (scn, prt, rate)):
            cells = [rmse.get((seq, scn, prt, e, rate)) for e in ests]
            lines.append(f"| {seq} | " + " | ".join("–" if v is None else v for v in cells) + " |")
        lines.append("")
    return lines


def _cell(r: ResultRow) -> str:
    """A row's RMSE in the per-sequence tables; a recorded estimate that is not ranked says what it covers."""
    c = r.coverage
    return f"{r.rmse_deg:.2f}" + ("" if ranked(r) or c is None else f" (covers {100 * c:.0f} %: not ranked)")
