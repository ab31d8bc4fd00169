"""Plots of ``riann-bag-eval`` results, after the paper's figures 7–9 (matplotlib, Agg backend; ROS-free)."""

from __future__ import annotations

import os
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from riann_ros.evaluation.aggregate import scenario_order
from riann_ros.evaluation.perturb import NONE
from riann_ros.evaluation.results import REFERENCE, ResultRow
from riann_ros.evaluation.scenarios import AS_RECORDED


def _plt():
    os.environ.setdefault("MPLBACKEND", "Agg")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


# Colours. The four built-in estimators keep theirs in every figure (tab10's blue, green, orange, red), whatever the
# order of -e. Every other label of a figure (a variant such as vqf(tau_acc=1), a tuned filter, a recorded topic, a
# file, a comparison) gets a colour of CANDIDATES at least MIN_DELTA_E (CIELAB ΔE*ab) from every colour already in
# the figure, taken in sorted label order so that the order of -e does not matter: for a variant of a built-in
# estimator the one nearest its estimator's colour (a lighter or darker shade where one is far enough), for any other
# label the one farthest from the rest. ΔE 20 is ten times the just-noticeable difference (~2.3), so two lines or
# points of a figure are told apart at a glance; when a figure holds more labels than the candidates allow at that
# distance (about 20), the farthest free colour is taken (test/test_evaluation_plots.py checks both).
FIXED_COLORS = {"riann": "#1f77b4", "vqf": "#2ca02c", "madgwick": "#ff7f0e", "mahony": "#d62728"}
MIN_DELTA_E = 20.0
# matplotlib's qualitative tables (tab20, tab20b, tab20c, Dark2, Set1) in that order, without greys (chroma < 20:
# the reference is drawn in grey-black, rest phases are shaded grey), colours too light to see on white (L* > 85),
# and FIXED_COLORS.
CANDIDATES = ("#ffbb78", "#98df8a", "#ff9896", "#9467bd", "#c5b0d5", "#8c564b", "#e377c2", "#f7b6d2", "#bcbd22",
              "#17becf", "#9edae5", "#393b79", "#5254a3", "#6b6ecf", "#9c9ede", "#637939", "#8ca252", "#b5cf6b",
              "#8c6d31", "#bd9e39", "#e7ba52", "#e7cb94", "#843c39", "#ad494a", "#d6616b", "#e7969c", "#7b4173",
              "#a55194", "#ce6dbd", "#de9ed6", "#3182bd", "#6baed6", "#e6550d", "#fd8d3c", "#fdae6b", "#31a354",
              "#74c476", "#a1d99b", "#756bb1", "#9e9ac8", "#1b9e77", "#d95f02", "#7570b3", "#e7298a", "#66a61e",
              "#e6ab02", "#a6761d", "#e41a1c", "#377eb8", "#4daf4a", "#984ea3", "#ff7f00", "#a65628", "#f781bf")


def lab(colors: Sequence[str]) -> np.ndarray:
    """CIELAB (D65) of hex sRGB colours, (N, 3)."""
    rgb = np.array([[int(c[i : i + 2], 16) / 255.0 for i in (1, 3, 5)] for c in colors]).reshape(-1, 3)
    lin = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
    xyz = lin @ np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]]).T
    xyz /= np.array([0.95047, 1.0, 1.08883])
    f = np.where(xyz > (6 / 29) ** 3, np.cbrt(xyz), xyz / (3 * (6 / 29) ** 2) + 4 / 29)
    return np.column_stack([116 * f[:, 1] - 16, 500 * (f[:, 0] - f[:, 1]), 200 * (f[:, 1] - f[:, 2])])


_CANDIDATE_LAB = lab(CANDIDATES)


def base_estimator(label: str) -> str | None:
    """The built-in estimator a label is a variant of (``vqf(tau_acc=1)`` → ``vqf``), or None."""
    base = label.split("(", 1)[0].split(":", 1)[0].strip()
    return base if base in FIXED_COLORS and base != label else None


def estimator_colors(labels: Sequence[str]) -> dict[str, str]:
    """The colour of each label of one figure (see :data:`FIXED_COLORS`)."""
    out = {lbl: FIXED_COLORS[lbl] for lbl in labels if lbl in FIXED_COLORS}
    for lbl in sorted(set(labels) - set(out)):
        used = lab(list(out.values()))
        free = np.array([c not in out.values() for c in CANDIDATES])
        dist = (np.sqrt(((_CANDIDATE_LAB[:, None, :] - used[None]) ** 2).sum(-1)).min(axis=1) if len(used)
                else np.full(len(CANDIDATES), np.inf))
        far = free & (dist >= MIN_DELTA_E)
        base = base_estimator(lbl)
        if base is not None and far.any():  # the shade nearest its estimator's colour that is far enough
            near = np.sqrt(((_CANDIDATE_LAB - lab([FIXED_COLORS[base]])) ** 2).sum(-1))
            k = int(np.argmin(np.where(far, near, np.inf)))
        else:
            k = int(np.argmax(np.where(free, dist, -np.inf)))
        out[lbl] = CANDIDATES[k]
    return out


def _save(fig, out_dir: Path, stem: str) -> list[Path]:
    paths = []
    for ext in ("png", "svg"):
        p = out_dir / f"{stem}.{ext}"
        fig.savefig(p, dpi=110 if ext == "png" else None, bbox_inches="tight")
        paths.append(p)
    _plt().close(fig)
    return paths


def _fig_legend(fig, ax, ncol: int) -> None:
    """One legend above all panels (after tight_layout, so it does not squeeze the axes)."""
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(
        handles, labels, loc="lower center", bbox_to_anchor=(0.5, 1.0), ncol=ncol, fontsize="small", frameon=False
    )


def _legend_labels(rows: Sequence[ResultRow], ests: list[str]) -> dict[str, str]:
    """``label (n=…)``: the number of sequences of each estimator in the figure."""
    return {e: f"{e} (n={len({r.sequence for r in rows if r.estimator == e})})" for e in ests}


BOX_MIN_N = 3  # fewer sequences: points only (a box of one or two values says nothing)


def _box_group(ax, vals: list[float], pos: float, width: float, color, seed: int, gid: str | None = None) -> None:
    """One estimator × dataset: a box (from BOX_MIN_N sequences on) and every sequence as a point over it."""
    if len(vals) >= BOX_MIN_N:
        bp = ax.boxplot([vals], positions=[pos], widths=width * 0.85, patch_artist=True, showfliers=False,
                        medianprops={"color": "k", "lw": 1.2}, whiskerprops={"color": "0.35"},
                        capprops={"color": "0.35"}, boxprops={"edgecolor": "0.35"}, manage_ticks=False)
        for box in bp["boxes"]:
            box.set_facecolor(color)
            box.set_alpha(0.35)
    jitter = np.random.default_rng(seed).uniform(-0.25, 0.25, len(vals)) * width if len(vals) > 1 else [0.0]
    ax.scatter(pos + np.asarray(jitter), vals, s=22 if len(vals) < 20 else 12, color=color, edgecolors="k",
               linewidths=0.5, zorder=3, gid=gid)
    if len(vals) == 1:  # one sequence: the number itself
        ax.annotate(f"{vals[0]:.2f}", (pos, vals[0]), xytext=(0, 6), textcoords="offset points", ha="center",
                    fontsize="x-small")


def conditions_of(rows: Sequence[ResultRow], chosen: Sequence[str] | None = None) -> list[str]:
    """The perturbation conditions of ``rows`` in their order, those in ``chosen`` only when given."""
    present = list(dict.fromkeys(r.perturbation for r in rows))
    return [c for c in present if chosen is None or c in chosen]


def _panel_title(scenario: str, condition: str, conditions: Sequence[str]) -> str:
    """The scenario, with the condition when it is not the only one and ``none``."""
    return scenario if list(conditions) == [NONE] else f"{scenario} — {condition}"


def plot_boxes(rows: Sequence[ResultRow], out_dir: Path, stem: str = "rmse_boxplots",
               conditions: Sequence[str] | None = None) -> list[Path]:
    """Figure 8 of the paper: RMSE per sequence per estimator, one panel per scenario × perturbation condition
    (every condition, or ``conditions``), grouped by dataset (native rates): every sequence a point over its box
    (boxes from BOX_MIN_N sequences on), a linear axis in degrees, the number of sequences in the legend."""
    plt = _plt()
    rows = [r for r in rows if not r.resampled]
    conds = conditions_of(rows, conditions)
    rows = [r for r in rows if r.perturbation in conds]
    if not rows:
        return []
    scenarios = scenario_order(r.scenario for r in rows)
    datasets = list(dict.fromkeys(r.dataset for r in rows))
    ests = list(dict.fromkeys(r.estimator for r in rows))
    colors = estimator_colors(ests)
    labels = _legend_labels(rows, ests)
    panel_w = max(3.2, 0.75 * len(datasets) * len(ests) + 0.8)
    cells = [(c, scn) for c in conds for scn in scenarios]
    if len(datasets) <= 2:  # few groups: scenarios side by side, a row per condition, one y axis per row
        fig, axes = plt.subplots(len(conds), len(scenarios), figsize=(panel_w * len(scenarios), 4.8 * len(conds)),
                                 squeeze=False, sharey="row")
        panels = [axes[i, j] for i in range(len(conds)) for j in range(len(scenarios))]
    else:
        fig, axes = plt.subplots(len(cells), 1, figsize=(max(6, panel_w), 3.2 * len(cells)), squeeze=False)
        panels = list(axes[:, 0])
    width = 0.8 / len(ests)
    for ax, (cond, scn) in zip(panels, cells, strict=True):
        sel = [r for r in rows if r.scenario == scn and r.perturbation == cond]
        for j, est in enumerate(ests):
            for i, d in enumerate(datasets):
                vals = [r.rmse_deg for r in sel if r.dataset == d and r.estimator == est]
                if vals:
                    _box_group(ax, vals, i + (j - (len(ests) - 1) / 2) * width, width, colors[est], seed=7 * j + i,
                               gid=f"estimator:{est}")
            ax.scatter([], [], s=30, color=colors[est], edgecolors="k", linewidths=0.5, label=labels[est])
        ax.set_xticks(range(len(datasets)), datasets)
        ax.set_xlim(-0.5, len(datasets) - 0.5)
        if ax is panels[0] or len(datasets) > 2 or scn == scenarios[0]:
            ax.set_ylabel("RMSE e_α (°) per sequence")
        ax.set_title(_panel_title(scn, cond, conds))
        ax.set_gid(f"panel:{scn}|{cond}")  # findable in the SVG
        ax.grid(axis="y", alpha=0.3)
        # from 0, with room for the labels above the points
        top = max([r.rmse_deg for r in (rows if len(datasets) <= 2 else sel) if r.perturbation == cond],
                  default=1.0)
        ax.set_ylim(0, top * 1.12 if top > 0 else 1.0)
    fig.tight_layout()
    _fig_legend(fig, panels[0], min(len(ests), 4))
    return _save(fig, out_dir, stem)


def _spans(mask: np.ndarray) -> list[tuple[int, int]]:
    m = np.concatenate([[False], mask.astype(bool), [False]])
    d = np.flatnonzero(np.diff(m.astype(int)))
    return list(zip(d[::2], d[1::2], strict=True))


def series_conditions(series: dict[str, Any], chosen: Sequence[str] | None = None) -> dict[str, dict[str, Any]]:
    """Condition → its series (``curves``, ``t``, ``scored``, ``attitude`` per scenario), those in ``chosen``
    only when given; a series without conditions is the ``none`` condition's."""
    conds = series.get("conditions") or {NONE: series}
    return {c: v for c, v in conds.items() if chosen is None or c in chosen}


def plot_error_over_time(series: dict[str, Any], out_dir: Path, stem: str = "error_over_time",
                         conditions: Sequence[str] | None = None) -> list[Path]:
    """Figure 7 of the paper: e_α over time for one sequence, a row of panels per scenario and a column per
    perturbation condition (every condition, or ``conditions``), rest (unscored) phases shaded."""
    plt = _plt()
    conds = series_conditions(series, conditions)
    if not conds:
        return []
    scenarios = scenario_order(s for c in conds.values() for s in c["curves"])
    fig, axes = plt.subplots(len(scenarios), len(conds), figsize=(10 if len(conds) == 1 else 6.5 * len(conds),
                                                                  2.8 * len(scenarios)), squeeze=False)
    labels = list(dict.fromkeys(lbl for c in conds.values() for cur in c["curves"].values() for lbl in cur))
    colors = estimator_colors(labels)
    for col, (cond, view) in enumerate(conds.items()):
        for row, scn in enumerate(scenarios):
            ax = axes[row, col]
            if scn not in view["curves"]:
                ax.set_visible(False)
                continue
            t = np.asarray(view["t"][scn], dtype=float)
            scored = np.asarray(view["scored"][scn], dtype=bool)
            for a, b in _spans(~scored):
                ax.axvspan(t[a], t[min(b, len(t) - 1)], color="0.85", lw=0, zorder=0)
            for label, e in view["curves"][scn].items():
                ax.plot(t, e, lw=0.8, label=label, color=colors[label], gid=f"estimator:{label}")
            ax.set_title(f"{series['sequence']} — {_panel_title(scn, cond, list(conds))} (grey: rest / not scored)",
                         fontsize="medium")
            ax.set_gid(f"panel:{scn}|{cond}")
            ax.set_ylabel("e_α (°)")
            ax.set_ylim(bottom=0)
            ax.grid(alpha=0.3)
        axes[-1, col].set_xlabel("time since start of the scenario sequence (s)")
    fig.tight_layout()
    _fig_legend(fig, axes[0, 0], 4)
    return _save(fig, out_dir, stem)


def plot_rmse_vs_rate(rows: Sequence[ResultRow], out_dir: Path, stem: str = "rmse_vs_rate",
                      conditions: Sequence[str] | None = None) -> list[Path]:
    """Figure 9 of the paper: mean RMSE (and min–max band) over all sequences versus sampling rate, per
    estimator, a panel per scenario and a row per perturbation condition. Only when several rates were
    evaluated."""
    plt = _plt()
    rows = [r for r in rows if r.resampled]
    conds = conditions_of(rows, conditions)
    rows = [r for r in rows if r.perturbation in conds]
    # the requested rate: a resampled sequence's own rate_hz differs from it by < 1 / its length
    rates = sorted({float(r.rate) for r in rows})
    if len(rates) < 2:
        return []
    scenarios = scenario_order(r.scenario for r in rows)
    ests = list(dict.fromkeys(r.estimator for r in rows))
    labels = _legend_labels(rows, ests)
    colors = estimator_colors(ests)
    fig, axes = plt.subplots(len(conds), len(scenarios), figsize=(5.5 * len(scenarios), 3.8 * len(conds)),
                             squeeze=False)
    for i, cond in enumerate(conds):
        for ax, scn in zip(axes[i], scenarios, strict=True):
            for est in ests:
                vals = [[r.rmse_deg for r in rows if r.scenario == scn and r.estimator == est and
                         r.perturbation == cond and float(r.rate) == f] for f in rates]
                mean = [np.mean(v) if v else np.nan for v in vals]
                lo = [np.min(v) if v else np.nan for v in vals]
                hi = [np.max(v) if v else np.nan for v in vals]
                ax.plot(rates, mean, "o-", label=labels[est], color=colors[est], gid=f"estimator:{est}")
                ax.fill_between(rates, lo, hi, color=colors[est], alpha=0.15)
            ax.set_xlabel("sampling rate (Hz)")
            ax.set_ylabel("RMSE e_α (°): mean, min–max")
            ax.set_title(_panel_title(scn, cond, conds))
            ax.set_gid(f"panel:{scn}|{cond}")
            ax.set_ylim(bottom=0)
            ax.grid(alpha=0.3)
    fig.tight_layout()
    _fig_legend(fig, axes[0, 0], min(len(ests), 4))
    return _save(fig, out_dir, stem)


def attitude_scenario(series: dict[str, Any]) -> str:
    """The scenario of the roll/pitch plot: ``as-recorded`` (the recording as it is, where recorded estimates are)
    when evaluated, else the first."""
    present = scenario_order(series.get("attitude", {}))
    return AS_RECORDED if AS_RECORDED in present else present[0]


def _breaks(a: np.ndarray) -> np.ndarray:
    """NaN where an angle wraps (jumps by more than 180°), so the line does not cross the plot."""
    a = np.asarray(a, dtype=float).copy()
    jump = np.flatnonzero(np.abs(np.diff(a)) > 180.0)
    a[jump + 1] = np.nan
    return a


def file_safe(text: str) -> str:
    """``text`` for a file name: runs of other characters than letters, digits, ``_``, ``.``, ``-`` → ``_``."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_")


def attitude_stem(sequence: str, condition: str = NONE) -> str:
    """``roll_pitch_<sequence>``, with ``_<condition>`` for a perturbation condition (file-name safe)."""
    return ("roll_pitch_" + (file_safe(sequence) or "sequence")
            + ("" if condition == NONE else "_" + file_safe(condition)))


def plot_attitude(series: dict[str, Any], out_dir: Path, scenario: str | None = None,
                  condition: str | None = None) -> list[Path]:
    """evo_traj-style: roll and pitch over time of the reference and of every estimator for one sequence (one
    scenario: :func:`attitude_scenario` by default; one perturbation condition: the first by default), with e_α
    below; unscored samples shaded. The file is ``roll_pitch_<sequence>[_<condition>]``."""
    plt = _plt()
    conds = series_conditions(series)
    condition = condition if condition is not None else next(iter(conds), NONE)
    view = conds.get(condition)
    if not view or not view.get("attitude"):
        return []
    scn = scenario or attitude_scenario(view)
    att = view["attitude"][scn]
    t = np.asarray(view["t"][scn], dtype=float)
    scored = np.asarray(view["scored"][scn], dtype=bool)
    fig, axes = plt.subplots(3, 1, figsize=(11, 7.5), sharex=True, gridspec_kw={"height_ratios": [2, 2, 1.3]})
    for ax in axes:
        for a, b in _spans(~scored):
            ax.axvspan(t[a], t[min(b, len(t) - 1)], color="0.9", lw=0, zorder=0)
    colors = estimator_colors(list(view["curves"][scn]))
    for k, name in enumerate(("roll", "pitch")):
        ax = axes[k]
        ax.plot(t, _breaks(att[REFERENCE][:, k]), color="k", lw=2.2, alpha=0.55, label="reference")
        for label, color in colors.items():
            ax.plot(t, _breaks(att[label][:, k]), lw=0.9, color=color, label=label, gid=f"estimator:{label}")
        ax.set_ylabel(f"{name} (°)")
        ax.grid(alpha=0.3)
    for label, e in view["curves"][scn].items():
        axes[2].plot(t, e, lw=0.8, color=colors[label])
    axes[2].set_ylabel("e_α (°)")
    axes[2].set_ylim(bottom=0)
    axes[2].grid(alpha=0.3)
    axes[2].set_xlabel("time since start of the scenario sequence (s)")
    what = scn if condition == NONE else f"{scn}, {condition}"
    axes[0].set_title(f"{series['sequence']} — {what}: roll and pitch, reference vs estimators (grey: not scored)")
    fig.tight_layout()
    _fig_legend(fig, axes[0], min(len(att), 5))
    return _save(fig, out_dir, attitude_stem(series["sequence"], condition))


def plot_differences(diffs: dict[tuple[str, str], list[float]], a_label: str, b_label: str, out_dir: Path,
                     stem: str = "compare_rmse", ylabel: str = "RMSE e_α") -> list[Path]:
    """``--compare``: per panel (scenario × perturbation × rate), the difference B − A of every sequence per tick
    (estimator, or ``A → B`` labels) as points, their mean as a bar, and zero (below zero: B is better); linear axis
    in degrees. ``diffs`` maps (panel, tick) to the per-sequence differences, in display order."""
    plt = _plt()
    panels = list(dict.fromkeys(k[0] for k in diffs))
    ticks = list(dict.fromkeys(k[1] for k in diffs))
    colors = estimator_colors(ticks)
    fig, axes = plt.subplots(1, len(panels), figsize=(max(3.6, 0.9 * len(ticks) + 1.2) * len(panels), 4.2),
                             squeeze=False, sharey=True)
    for ax, panel in zip(axes[0], panels, strict=True):
        ax.axhline(0.0, color="k", lw=0.8)
        labels = []
        for j, tick in enumerate(ticks):
            d = diffs.get((panel, tick), [])
            labels.append(f"{tick.replace(' → ', chr(10) + '→ ')}\n(n={len(d)})")
            if not d:
                continue
            jitter = np.random.default_rng(j).uniform(-0.18, 0.18, len(d)) if len(d) > 1 else [0.0]
            ax.scatter(j + np.asarray(jitter), d, s=22, color=colors[tick], edgecolors="k", linewidths=0.5,
                       zorder=3, gid=f"estimator:{tick}")
            ax.hlines(np.mean(d), j - 0.3, j + 0.3, color=colors[tick], lw=2.5, zorder=2)
        ax.set_xticks(range(len(ticks)), labels, fontsize="small")
        ax.set_xlim(-0.6, len(ticks) - 0.4)
        ax.set_title(panel or "all")
        ax.grid(axis="y", alpha=0.3)
    axes[0, 0].set_ylabel(f"{ylabel} B − A (°) per sequence\n(B = {b_label}, A = {a_label})")
    fig.suptitle("below 0: B better; bar: mean over the sequences", fontsize="small", y=1.0)
    fig.tight_layout()
    return _save(fig, out_dir, stem)
