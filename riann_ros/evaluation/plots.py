"""Plots of ``riann-bag-eval`` results, after the paper's figures 7–9 (matplotlib, Agg backend; ROS-free)."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from riann_ros.evaluation.aggregate import scenario_order
from riann_ros.evaluation.run import ResultRow


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


def plot_boxes(rows: Sequence[ResultRow], out_dir: Path, stem: str = "rmse_boxplots") -> list[Path]:
    """Figure 8 of the paper: RMSE distribution per estimator, one panel per scenario, grouped by dataset
    (native rates only)."""
    plt = _plt()
    rows = [r for r in rows if not r.resampled]
    if not rows:
        return []
    scenarios = scenario_order(r.scenario for r in rows)
    datasets = list(dict.fromkeys(r.dataset for r in rows))
    ests = list(dict.fromkeys(r.estimator for r in rows))
    colors = plt.get_cmap("tab10").colors
    panel_w = max(3.2, 0.9 * len(datasets) * len(ests))
    if len(datasets) <= 2:  # few groups: scenarios side by side, one y axis
        fig, axes = plt.subplots(1, len(scenarios), figsize=(panel_w * len(scenarios), 4.0), squeeze=False, sharey=True)
        panels = axes[0]
    else:
        fig, axes = plt.subplots(len(scenarios), 1, figsize=(max(6, panel_w), 3.2 * len(scenarios)), squeeze=False)
        panels = axes[:, 0]
    width = 0.8 / len(ests)
    for ax, scn in zip(panels, scenarios, strict=True):
        for j, est in enumerate(ests):
            data = [
                [r.rmse_deg for r in rows if r.scenario == scn and r.dataset == d and r.estimator == est]
                for d in datasets
            ]
            pos = [i + (j - (len(ests) - 1) / 2) * width for i in range(len(datasets))]
            ok = [(p, d) for p, d in zip(pos, data, strict=True) if d]
            if not ok:
                continue
            bp = ax.boxplot(
                [d for _, d in ok],
                positions=[p for p, _ in ok],
                widths=width * 0.85,
                patch_artist=True,
                showmeans=True,
                meanprops={"marker": "^", "markerfacecolor": "white", "markeredgecolor": "k"},
            )
            for box in bp["boxes"]:
                box.set_facecolor(colors[j % len(colors)])
                box.set_alpha(0.75)
            ax.plot([], [], "s", color=colors[j % len(colors)], label=est)
        ax.set_xticks(range(len(datasets)), datasets)
        if ax is panels[0] or len(datasets) > 2:
            ax.set_ylabel("RMSE e_α (°) per sequence")
        ax.set_title(scn)
        ax.grid(axis="y", alpha=0.3)
        ax.set_yscale("log")
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
    rows = [r for r in rows if r.resampled]
    rates = sorted({r.rate_hz for r in rows})
    if len(rates) < 2:
        return []
    scenarios = scenario_order(r.scenario for r in rows)
    ests = list(dict.fromkeys(r.estimator for r in rows))
    fig, axes = plt.subplots(1, len(scenarios), figsize=(5.5 * len(scenarios), 3.8), squeeze=False)
    for ax, scn in zip(axes[0], scenarios, strict=True):
        for est in ests:
            vals = [
                [r.rmse_deg for r in rows if r.scenario == scn and r.estimator == est and r.rate_hz == f]
                for f in rates
            ]
            mean = [np.mean(v) if v else np.nan for v in vals]
            lo = [np.min(v) if v else np.nan for v in vals]
            hi = [np.max(v) if v else np.nan for v in vals]
            (line,) = ax.plot(rates, mean, "o-", label=est)
            ax.fill_between(rates, lo, hi, color=line.get_color(), alpha=0.15)
        ax.set_xlabel("sampling rate (Hz)")
        ax.set_ylabel("RMSE e_α (°): mean, min–max")
        ax.set_title(scn)
        ax.set_yscale("log")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize="small")
    fig.tight_layout()
    return _save(fig, out_dir, stem)
