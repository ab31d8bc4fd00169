"""The text ``riann-bag-eval --compare`` prints for a :class:`~riann_ros.evaluation.compare.Comparison`: per group,
per sequence, every statistic per sequence, and the rows without a partner (ROS-free)."""

from __future__ import annotations

import json
import math
import shlex

from riann_ros.evaluation.compare import (
    AXES,
    PRINT_PAIRS,
    Comparison,
    Saved,
    Side,
    metric_text,
    ordered_pairs,
    pair_stat,
    rate_text,
    side_of,
    side_text,
)
from riann_ros.evaluation.perturb import NONE
from riann_ros.evaluation.results import NATIVE, ResultRow
from riann_ros.evaluation.scoring import STATS
from riann_ros.evaluation.uncertainty_report import format_uncertainty_comparison

#: results.json settings that change every score of a run: said when A's and B's differ
SCORE_SETTINGS = {"seed": "seed", "rest": "initial rest (--rest)", "score_from_s": "--score-from",
                  "offset_steps": "--offset-steps", "bias_std_dps": "the scenarios' gyro bias σ (°/s)",
                  "reference_sd_deg": "--reference-sd (the uncertainty scores)"}


def setting_differences(a: Saved, b: Saved) -> list[str]:
    """The score-changing settings (:data:`SCORE_SETTINGS`) A and B were run with otherwise, as ``NAME: A …, B …``
    (a setting an older results.json lacks is not compared)."""
    return [f"{name}: A {json.dumps(a.settings[k])}, B {json.dumps(b.settings[k])}"
            for k, name in SCORE_SETTINGS.items()
            if k in a.settings and k in b.settings and a.settings[k] != b.settings[k]]


def _table(headers: list[str], rows: list[list[str]], numeric: set[str]) -> list[str]:
    widths = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(headers)]

    def fmt(row: list[str]) -> str:
        return "  ".join(c.rjust(w) if h in numeric else c.ljust(w) for c, w, h in zip(row, widths, headers,
                                                                                       strict=True))

    return [fmt(headers), "  ".join("-" * w for w in widths), *(fmt(r) for r in rows)]


class _Layout:
    """Which side columns a comparison's tables show: each differing axis as ``<axis> A`` and ``<axis> B``, then
    the matched axes once (perturbation and rate only when they are not all ``none`` / one rate)."""

    def __init__(self, cmp: Comparison) -> None:
        sides = [s for p in cmp.pairs for s in (side_of(p.a), side_of(p.b))]
        shown = []
        for ax in AXES:
            vals = {s[AXES.index(ax)] for s in sides}
            if ax in cmp.differing or ax in ("estimator", "scenario") or (
                    ax == "perturbation" and vals != {NONE}) or (ax in ("rate", "sensors") and len(vals) > 1):
                shown.append(ax)
        self.axes = shown
        self.differing = cmp.differing
        self.headers = [h for ax in shown for h in ((f"{ax} A", f"{ax} B") if ax in self.differing else (ax,))]

    def cells(self, a: Side, b: Side) -> list[str]:
        return [c for ax in self.axes for c in ((side_text(a, ax), side_text(b, ax)) if ax in self.differing
                                                else (side_text(a, ax),))]


def _how(cmp: Comparison) -> list[str]:
    """How the rows were paired, and what makes A's and B's figures differ besides the estimators: the axes they do
    not share (9D against 6D said in words), the run settings they differ in."""
    sel = [f"{n}: {s.text()}" for n, s in zip("AB", cmp.selections, strict=True) if s.items]
    text = "rows paired by sequence" + (f", {', '.join(cmp.matched)}" if cmp.matched else "")
    if cmp.differing:
        text += f"; A and B differ in {' and '.join(cmp.differing)} (each side's shown)"
    lines = [text + (f"; selected {'; '.join(sel)}" if sel else "")]
    if "sensors" in cmp.differing:
        sa = "/".join(sorted({p.a.sensors for p in cmp.pairs}))
        sb = "/".join(sorted({p.b.sensors for p in cmp.pairs}))
        lines.append(f"NOTE: the sensors differ: A's rows are {sa}, B's {sb} (9D: the estimators used the "
                     "magnetometer): not the same condition (--select sensors=6D on both sides compares like with "
                     "like)")
    differ = setting_differences(cmp.a, cmp.b)
    if differ:
        lines.append("NOTE: A and B were run with other settings, which every difference includes: "
                     + "; ".join(differ))
    return lines


def format_comparison(cmp: Comparison) -> str:
    """The text of ``--compare``: per group, then per sequence (the metric, then every statistic of e_α); B − A,
    negative = B better."""
    lay = _Layout(cmp)
    groups = cmp.groups()
    stats = ("mean", "median", "max")
    headers = [*lay.headers, "n"] + [f"{s} {x}" for s in stats for x in ("A", "B", "B-A")]
    rows = [lay.cells(g.a_side, g.b_side) + [str(g.n)]
            + [f"{v:+.2f}" if x == "B-A" else f"{v:.2f}" for s in stats
               for x, v in (("A", g.a[s]), ("B", g.b[s]), ("B-A", g.diff(s)))]
            for g in groups]
    out = [f"A = {cmp.a.label}: {cmp.a.path}" + (f"  ({cmp.a.command})" if cmp.a.command else ""),
           f"B = {cmp.b.label}: {cmp.b.path}" + (f"  ({cmp.b.command})" if cmp.b.command else ""),
           *_how(cmp), "",
           f"{metric_text(cmp.metric)} (°) per sequence, B − A (negative: B is better)",
           *_table(headers, rows, {"n", *headers[len(lay.headers) + 1:]}), "", "per sequence"]
    seq_rows = [[*lay.cells(side_of(p.a), side_of(p.b)), p.sequence, f"{p.va:.2f}", f"{p.vb:.2f}",
                 f"{p.diff:+.2f}"] for p in ordered_pairs(cmp)]
    out += _table([*lay.headers, "sequence", "A", "B", "B-A"], seq_rows, {"A", "B", "B-A"})
    out += _statistics(cmp, lay)
    out += format_uncertainty_comparison([(p.a, p.b) for p in ordered_pairs(cmp)])
    for name, rows_only in (("A", cmp.only_a), ("B", cmp.only_b)):
        if rows_only:
            shown = ", ".join(_row_text(r) for r in rows_only[:5]) + (" …" if len(rows_only) > 5 else "")
            out.append(f"only in {name} (no partner in {'B' if name == 'A' else 'A'}): {len(rows_only)} row(s): "
                       f"{shown}")
    if cmp.only_a and cmp.only_b and "estimator" in cmp.matched:
        la = list(dict.fromkeys(r.estimator for r in cmp.only_a))
        lb = list(dict.fromkeys(r.estimator for r in cmp.only_b))
        pick = (f"--select-a estimator={shlex.quote(la[0])} --select-b estimator={shlex.quote(lb[0])}"
                if len(la) == len(lb) == 1 else "--select-a estimator=LABEL --select-b estimator=OTHER")
        out.append(f"rows with different labels pair when they are selected: {pick}")
    if cmp.without_metric:
        out.append(f"{cmp.without_metric} pair(s) without the {metric_text(cmp.metric)} on one side: not compared")
    return "\n".join(out)


def _statistics(cmp: Comparison, lay: _Layout) -> list[str]:
    """evo_res's table per sequence: every statistic of e_α for A, B and B − A."""
    pairs = ordered_pairs(cmp)
    title = "e_α statistics per sequence (°): A, B and B − A"
    if len(pairs) > PRINT_PAIRS:
        return ["", f"{title}: {len(pairs)} pairs, in compare.csv"]
    rows = []
    for p in pairs:
        va = {st: pair_stat(p.a, ("inclination", st)) for st in STATS}
        vb = {st: pair_stat(p.b, ("inclination", st)) for st in STATS}
        lead = [*lay.cells(side_of(p.a), side_of(p.b)), p.sequence]
        for run, vals in (("A", va), ("B", vb), ("B-A", {st: vb[st] - va[st] for st in STATS})):
            rows.append([*(lead if run == "A" else [""] * len(lead)), run,
                         *("–" if not math.isfinite(v) else (f"{v:+.2f}" if run == "B-A" else f"{v:.2f}")
                           for v in vals.values())])
    return ["", title, *_table([*lay.headers, "sequence", "run", *STATS], rows, set(STATS))]


def _row_text(r: ResultRow) -> str:
    """``sequence/scenario[/perturbation][/rate]/estimator``."""
    return "/".join([r.sequence, r.scenario, *([r.perturbation] if r.perturbation != NONE else []),
                     *([rate_text(r.rate)] if r.rate != NATIVE else []), r.estimator])
