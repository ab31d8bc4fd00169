"""Plots of ``riann-bag-eval`` results, after the paper's figures 7–9 (matplotlib, Agg backend; ROS-free)."""

from __future__ import annotations

import os
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from riann_ros.evaluation.aggregate import rate_label, scenario_order
from riann_ros.evaluation.perturb import NONE
from riann_ros.evaluation.results import REFERENCE, ResultRow
from riann_ros.evaluation.scenarios import AS_RECORDED


def _plt():
    os.environ.setdefault("MPLBACKEND", "Agg")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


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


def _box_group(ax, vals: list[float], pos: float, width: float, color, seed: int) -> None:
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
               linewidths=0.5, zorder=3)
    if len(vals) == 1:  # one sequence: the number itself
        ax.annotate(f"{vals[0]:.2f}", (pos, vals[0]), xytext=(0, 6), textcoords="offset points", ha="center",
                    fontsize="x-small")


def plot_boxes(rows: Sequence[ResultRow], out_dir: Path, stem: str = "rmse_boxplots") -> list[Path]:
    """Figure 8 of the paper: RMSE per sequence per estimator, one panel per scenario, grouped by dataset (native
    rates, unperturbed rows): every sequence a point over its box (boxes from BOX_MIN_N sequences on), a linear axis
    in degrees, the number of sequences in the legend."""
    plt = _plt()
    rows = [r for r in rows if not r.resampled and r.perturbation == NONE] or [r for r in rows if not r.resampled]
    if not rows:
        return []
    scenarios = scenario_order(r.scenario for r in rows)
    datasets = list(dict.fromkeys(r.dataset for r in rows))
    ests = list(dict.fromkeys(r.estimator for r in rows))
    colors = plt.get_cmap("tab10").colors
    labels = _legend_labels(rows, ests)
    panel_w = max(3.2, 0.75 * len(datasets) * len(ests) + 0.8)
    if len(datasets) <= 2:  # few groups: scenarios side by side, one y axis
        fig, axes = plt.subplots(1, len(scenarios), figsize=(panel_w * len(scenarios), 4.8), squeeze=False, sharey=True)
        panels = axes[0]
    else:
        fig, axes = plt.subplots(len(scenarios), 1, figsize=(max(6, panel_w), 3.2 * len(scenarios)), squeeze=False)
        panels = axes[:, 0]
    width = 0.8 / len(ests)
    for ax, scn in zip(panels, scenarios, strict=True):
        for j, est in enumerate(ests):
            color = colors[j % len(colors)]
            for i, d in enumerate(datasets):
                vals = [r.rmse_deg for r in rows if r.scenario == scn and r.dataset == d and r.estimator == est]
                if vals:
                    _box_group(ax, vals, i + (j - (len(ests) - 1) / 2) * width, width, color, seed=7 * j + i)
            ax.scatter([], [], s=30, color=color, edgecolors="k", linewidths=0.5, label=labels[est])
        ax.set_xticks(range(len(datasets)), datasets)
        ax.set_xlim(-0.5, len(datasets) - 0.5)
        if ax is panels[0] or len(datasets) > 2:
            ax.set_ylabel("RMSE e_α (°) per sequence")
        ax.set_title(scn)
        ax.grid(axis="y", alpha=0.3)
    for ax, scn in zip(panels, scenarios, strict=True):  # from 0, with room for the labels above the points
        top = max([r.rmse_deg for r in rows if len(datasets) <= 2 or r.scenario == scn], default=1.0)
        ax.set_ylim(0, top * 1.12 if top > 0 else 1.0)
    fig.tight_layout()
    _fig_legend(fig, axes[0, 0], min(len(ests), 4))
    return _save(fig, out_dir, stem)


def _spans(mask: np.ndarray) -> list[tuple[int, int]]:
    m = np.concatenate([[False], mask.astype(bool), [False]])
    d = np.flatnonzero(np.diff(m.astype(int)))
    return list(zip(d[::2], d[1::2], strict=True))


def plot_error_over_time(series: dict[str, Any], out_dir: Path, stem: str = "error_over_time") -> list[Path]:
    """Figure 7 of the paper: e_α over time for one sequence, one panel per scenario, rest (unscored)
    phases shaded."""
    plt = _plt()
    scenarios = scenario_order(series["curves"])
    fig, axes = plt.subplots(len(scenarios), 1, figsize=(10, 2.8 * len(scenarios)), squeeze=False, sharex=False)
    for ax, scn in zip(axes[:, 0], scenarios, strict=True):
        t = np.asarray(series["t"][scn], dtype=float)
        scored = np.asarray(series["scored"][scn], dtype=bool)
        for a, b in _spans(~scored):
            ax.axvspan(t[a], t[min(b, len(t) - 1)], color="0.85", lw=0, zorder=0)
        for label, e in series["curves"][scn].items():
            ax.plot(t, e, lw=0.8, label=label)
        ax.set_title(f"{series['sequence']} — {scn} (grey: rest / not scored)")
        ax.set_ylabel("e_α (°)")
        ax.set_ylim(bottom=0)
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time since start of the scenario sequence (s)")
    fig.tight_layout()
    _fig_legend(fig, axes[0, 0], 4)
    return _save(fig, out_dir, stem)


def plot_rmse_vs_rate(rows: Sequence[ResultRow], out_dir: Path, stem: str = "rmse_vs_rate") -> list[Path]:
    """Figure 9 of the paper: mean RMSE (and min–max band) over all sequences versus sampling rate, per
    estimator and scenario. Only when several rates were evaluated."""
    plt = _plt()
    rows = [r for r in rows if r.resampled and r.perturbation == NONE]
    # the requested rate: a resampled sequence's own rate_hz differs from it by < 1 / its length
    rates = sorted({float(r.rate) for r in rows})
    if len(rates) < 2:
        return []
    scenarios = scenario_order(r.scenario for r in rows)
    ests = list(dict.fromkeys(r.estimator for r in rows))
    labels = _legend_labels(rows, ests)
    fig, axes = plt.subplots(1, len(scenarios), figsize=(5.5 * len(scenarios), 3.8), squeeze=False)
    for ax, scn in zip(axes[0], scenarios, strict=True):
        for est in ests:
            vals = [
                [r.rmse_deg for r in rows if r.scenario == scn and r.estimator == est and float(r.rate) == f]
                for f in rates
            ]
            mean = [np.mean(v) if v else np.nan for v in vals]
            lo = [np.min(v) if v else np.nan for v in vals]
            hi = [np.max(v) if v else np.nan for v in vals]
            (line,) = ax.plot(rates, mean, "o-", label=labels[est])
            ax.fill_between(rates, lo, hi, color=line.get_color(), alpha=0.15)
        ax.set_xlabel("sampling rate (Hz)")
        ax.set_ylabel("RMSE e_α (°): mean, min–max")
        ax.set_title(scn)
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


def attitude_stem(sequence: str) -> str:
    return "roll_pitch_" + (re.sub(r"[^A-Za-z0-9_.-]+", "_", sequence).strip("_") or "sequence")


def plot_attitude(series: dict[str, Any], out_dir: Path, scenario: str | None = None) -> list[Path]:
    """evo_traj-style: roll and pitch over time of the reference and of every estimator for one sequence (one
    scenario: :func:`attitude_scenario` by default), with e_α below; unscored samples shaded."""
    plt = _plt()
    if not series.get("attitude"):
        return []
    scn = scenario or attitude_scenario(series)
    att = series["attitude"][scn]
    t = np.asarray(series["t"][scn], dtype=float)
    scored = np.asarray(series["scored"][scn], dtype=bool)
    fig, axes = plt.subplots(3, 1, figsize=(11, 7.5), sharex=True, gridspec_kw={"height_ratios": [2, 2, 1.3]})
    for ax in axes:
        for a, b in _spans(~scored):
            ax.axvspan(t[a], t[min(b, len(t) - 1)], color="0.9", lw=0, zorder=0)
    cycle = plt.get_cmap("tab10").colors
    colors = {label: cycle[i % len(cycle)] for i, label in enumerate(series["curves"][scn])}
    for k, name in enumerate(("roll", "pitch")):
        ax = axes[k]
        ax.plot(t, _breaks(att[REFERENCE][:, k]), color="k", lw=2.2, alpha=0.55, label="reference")
        for label, color in colors.items():
            ax.plot(t, _breaks(att[label][:, k]), lw=0.9, color=color, label=label)
        ax.set_ylabel(f"{name} (°)")
        ax.grid(alpha=0.3)
    for label, e in series["curves"][scn].items():
        axes[2].plot(t, e, lw=0.8, color=colors[label])
    axes[2].set_ylabel("e_α (°)")
    axes[2].set_ylim(bottom=0)
    axes[2].grid(alpha=0.3)
    axes[2].set_xlabel("time since start of the scenario sequence (s)")
    axes[0].set_title(f"{series['sequence']} — {scn}: roll and pitch, reference vs estimators (grey: not scored)")
    fig.tight_layout()
    _fig_legend(fig, axes[0], min(len(att), 5))
    return _save(fig, out_dir, attitude_stem(series["sequence"]))


def plot_differences(diffs: dict[tuple[str, str, str | float, str], list[float]], a_label: str, b_label: str,
                     out_dir: Path, stem: str = "compare_rmse") -> list[Path]:
    """``--compare``: per scenario (× perturbation × rate), the RMSE difference B − A of every sequence per
    estimator as points, their mean as a bar, and zero (below zero: B is better); linear axis in degrees.
    ``diffs`` maps (scenario, perturbation, rate, estimator) to the per-sequence differences, in display order."""
    plt = _plt()
    panels = list(dict.fromkeys(k[:3] for k in diffs))
    ests = list(dict.fromkeys(k[3] for k in diffs))
    colors = plt.get_cmap("tab10").colors
    fig, axes = plt.subplots(1, len(panels), figsize=(max(3.6, 0.9 * len(ests) + 1.2) * len(panels), 4.2),
                             squeeze=False, sharey=True)
    for ax, (scn, prt, rate) in zip(axes[0], panels, strict=True):
        ax.axhline(0.0, color="k", lw=0.8)
        ticks = []
        for j, est in enumerate(ests):
            d = diffs.get((scn, prt, rate, est), [])
            ticks.append(f"{est}\n(n={len(d)})")
            if not d:
                continue
            jitter = np.random.default_rng(j).uniform(-0.18, 0.18, len(d)) if len(d) > 1 else [0.0]
            ax.scatter(j + np.asarray(jitter), d, s=22, color=colors[j % len(colors)], edgecolors="k",
                       linewidths=0.5, zorder=3)
            ax.hlines(np.mean(d), j - 0.3, j + 0.3, color=colors[j % len(colors)], lw=2.5, zorder=2)
        ax.set_xticks(range(len(ests)), ticks, fontsize="small")
        ax.set_xlim(-0.6, len(ests) - 0.4)
        extra = ("" if prt == NONE else f", {prt}") + ("" if rate == "native" else f", {rate_label(rate)} Hz")
        ax.set_title(scn + extra)
        ax.grid(axis="y", alpha=0.3)
    axes[0, 0].set_ylabel(f"RMSE e_α B − A (°) per sequence\n(B = {b_label}, A = {a_label})")
    fig.suptitle("below 0: B better; bar: mean over the sequences", fontsize="small", y=1.0)
    fig.tight_layout()
    return _save(fig, out_dir, stem)
