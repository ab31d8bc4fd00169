"""The offline calibration's figures (matplotlib, Agg backend; ROS-free): the field before and after (the sphere,
three projections) and the heading before and after (:mod:`.bag_fit`)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from riann_ros.magcal.bag_fit import RecordingFit

MAX_POINTS = 4000  # readings drawn per figure at most (evenly spaced): a scatter of more is no clearer
RAW_COLOR, CAL_COLOR = "#7f7f7f", "#1f77b4"


def _plt():
    os.environ.setdefault("MPLBACKEND", "Agg")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _every(n: int) -> slice:
    return slice(None, None, max(1, -(-n // MAX_POINTS)))


def plot_sphere(rf: RecordingFit, path: Path, title: str = "") -> Path:
    """Raw and calibrated readings (µT) in the xy, xz and yz planes, with the calibrated field's sphere (its
    median norm) and the hard iron (the raw readings' centre)."""
    plt = _plt()
    fig, axes = plt.subplots(1, 3, figsize=(13, 4.6))
    pick = _every(rf.readings)
    raw, cal = rf.raw_ut[pick], rf.cal_ut[pick]
    h = np.asarray(rf.fit.calibration.hard_iron_t) * 1e6
    r = rf.fit.field_norm_ut
    circle = np.linspace(0.0, 2.0 * np.pi, 200)
    for ax, (i, j) in zip(axes, [(0, 1), (0, 2), (1, 2)], strict=True):
        ax.scatter(raw[:, i], raw[:, j], s=2, color=RAW_COLOR, alpha=0.4, label="raw", rasterized=True)
        ax.scatter(cal[:, i], cal[:, j], s=2, color=CAL_COLOR, alpha=0.4, label="calibrated", rasterized=True)
        ax.plot(r * np.cos(circle), r * np.sin(circle), color="black", lw=0.8,
                label=f"sphere |m| = {r:.1f} µT")
        ax.plot([h[i]], [h[j]], marker="x", color="#d62728", ms=9, mew=2, ls="none", label="hard iron")
        ax.set_xlabel(f"{'xyz'[i]} (µT)")
        ax.set_ylabel(f"{'xyz'[j]} (µT)")
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="best", fontsize=8)
    fig.suptitle(f"{title}field: raw |m| σ {rf.norm_sd_raw_ut:.2f} µT, calibrated |m| σ "
                 f"{rf.fit.field_norm_sd_ut:.2f} µT")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_heading(rf: RecordingFit, path: Path, title: str = "") -> Path:
    """The direction of magnetic north in the gyro-carried frame over time (raw, calibrated) and the field's norm."""
    plt = _plt()
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(11, 6.5), sharex=True)
    pick = _every(rf.readings)
    t = rf.t[pick]
    for north, color, label, spread in ((rf.north_raw_rad, RAW_COLOR, "raw", rf.north_spread_raw_deg),
                                        (rf.north_cal_rad, CAL_COLOR, "calibrated", rf.north_spread_cal_deg)):
        a1.plot(t, np.degrees(np.unwrap(north))[pick], color=color, lw=0.9,
                label=f"{label}: spread {spread:.1f}°")
    a1.set_ylabel("north in the gyro frame (°)")
    a1.legend(loc="best", fontsize=8)
    a1.grid(alpha=0.3)
    a2.plot(t, np.linalg.norm(rf.raw_ut[pick], axis=1), color=RAW_COLOR, lw=0.9, label="raw")
    a2.plot(t, np.linalg.norm(rf.cal_ut[pick], axis=1), color=CAL_COLOR, lw=0.9, label="calibrated")
    a2.set_ylabel("|m| (µT)")
    a2.set_xlabel("time (s)")
    a2.legend(loc="best", fontsize=8)
    a2.grid(alpha=0.3)
    fig.suptitle(f"{title}heading before and after: a calibrated field keeps north still while the sensor turns")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
