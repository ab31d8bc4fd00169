"""The figure of an input without a reference (ROS-free): roll, pitch and heading of every estimator over time,
overlaid, each with the band of the σ it reports (``attitude_<sequence>[_<condition>]``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from riann_ros.evaluation.perturb import NONE
from riann_ros.evaluation.plots import _breaks, _fig_legend, _plt, _save, estimator_colors, file_safe

#: °, a heading σ above this is no band but "heading unknown" (the 6D estimators' constant 180°)
HEADING_BAND_MAX_DEG = 90.0


def attitude_overlay_stem(sequence: str, condition: str = NONE) -> str:
    """``attitude_<sequence>``, with ``_<condition>`` for a perturbation condition (file-name safe)."""
    return "attitude_" + (file_safe(sequence) or "sequence") + ("" if condition == NONE else "_" + file_safe(condition))


def plot_attitude_overlay(series: dict[str, Any], out_dir: Path, condition: str | None = None) -> list[Path]:
    """Roll, pitch (Z-Y-X Euler angles, independent of the heading) and heading over time of every estimator of one
    input without a reference, with ±σ bands where the estimator reports a σ (inclination per axis for roll and
    pitch; the heading's when below :data:`HEADING_BAND_MAX_DEG`). A 6D estimator's heading starts wherever it
    initialises: compare their drift, not their values."""
    plt = _plt()
    conds = series.get("conditions", {})
    condition = condition if condition is not None else next(iter(conds), NONE)
    view = conds.get(condition)
    if not view or not len(view["t"]):
        return []
    t = np.asarray(view["t"], dtype=float)
    colors = estimator_colors(list(view["attitude"]))
    fig, axes = plt.subplots(3, 1, figsize=(11, 8), sharex=True)
    for k, name in enumerate(("roll", "pitch", "heading")):
        ax = axes[k]
        for label, color in colors.items():
            a = np.asarray(view["attitude"][label][:, k], dtype=float)
            ax.plot(t, _breaks(a), lw=0.9, color=color, label=label, gid=f"estimator:{label}")
            sig = np.asarray(view["sigma"][label][:, 1 if k == 2 else 0], dtype=float)
            if k == 2:
                sig = np.where(sig <= HEADING_BAND_MAX_DEG, sig, np.nan)
            if np.isfinite(sig).any():
                ax.fill_between(t, a - sig, a + sig, color=color, alpha=0.15, lw=0)
        ax.set_ylabel(f"{name} (°)")
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time since the first sample (s)")
    what = series.get("scenario", "as-recorded") + ("" if condition == NONE else f", {condition}")
    axes[0].set_title(f"{series['sequence']} — {what}, no reference: every estimator with ±σ (bands)")
    fig.tight_layout()
    _fig_legend(fig, axes[0], min(len(colors), 5))
    return _save(fig, out_dir, attitude_overlay_stem(series["sequence"], condition))
