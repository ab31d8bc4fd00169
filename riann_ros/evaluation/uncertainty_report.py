"""The uncertainty scores (:mod:`riann_ros.evaluation.uncertainty`) in tables, ``--compare`` and a plot (ROS-free)."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from riann_ros.defaults import INCLINATION_SD_DEG, MAG_HEADING_SD_DEG, YAW_FREE_SD_DEG
from riann_ros.evaluation import plots as pl
from riann_ros.evaluation.aggregate import rate_label
from riann_ros.evaluation.results import ResultRow
from riann_ros.evaluation.seq_tables import aligned
from riann_ros.evaluation.uncertainty import BINS, FIELD_USED_SD_DEG, decile_errors

NOTE = ("Roll and pitch errors as a 2-D Gaussian with the reported σ per axis: the share of scored samples inside the "
        "95 % region (e²/σ² ≤ 5.991; pooled, and the range over the sequences), the mean NEES per degree of freedom "
        "(1 when calibrated), and the mean error in the top decile of σ over the bottom decile's (all samples). The "
        "heading (1 DOF, 3.841) on samples whose σ is below 180°: while a field corrects it (\"field used\": the "
        f"state the estimator reports, else a heading σ of at most {FIELD_USED_SD_DEG:g}°), and while it is held by "
        f"the gyro after one. Madgwick, Mahony and VQF report constants ({INCLINATION_SD_DEG:g}°; heading "
        f"{YAW_FREE_SD_DEG:g}°, {MAG_HEADING_SD_DEG:g}° with a field, combined with a converging magnetometer "
        "calibration's share).")
TABLE_HEADERS = ["scenario", "perturbation", "rate", "estimator", "n", "cover95 %", "cover95 min–max %", "NEES/DOF",
                 "err top/bottom σ decile", "yaw cover95 % field used", "yaw cover95 % held", "yaw NEES"]
DATASET_HEADERS = ["dataset", "sensors", "estimator", "sequences", "cover95 %", "NEES/DOF"]


def _pooled(values: list[float | None], weights: list[float]) -> float | None:
    pairs = [(v, w) for v, w in zip(values, weights, strict=True) if v is not None and w > 0]
    total = sum(w for _, w in pairs)
    return sum(v * w for v, w in pairs) / total if total else None


def group_scores(grp: Sequence[ResultRow]) -> dict[str, float | None]:
    """The uncertainty scores of a group of rows (one estimator × scenario × perturbation × rate over sequences):
    coverage and NEES pooled over their scored samples, coverage's range over the sequences, sharpness as the mean
    error in the top decile of σ over that in the bottom decile, of all their samples (from the σ histograms; for
    rows without, each sequence's deciles pooled), the heading's coverage pooled over the samples with the field
    used and held."""
    sc = [r.score for r in grp]
    n = [float(s.n_scored) for s in sc]
    cov = [s.cover95_pct for s in sc]
    ny = [float((s.n_yaw_mag or 0) + (s.n_yaw_held or 0)) for s in sc]
    hist = pooled_histogram(grp)
    top: float | None
    bottom: float | None
    if hist is not None:  # the deciles of all the group's samples
        bottom, top = decile_errors(*hist)
    else:  # older results.json files: each sequence's deciles, pooled
        top = _pooled([s.err_top_decile_deg for s in sc], n)
        bottom = _pooled([s.err_bottom_decile_deg for s in sc], n)
    return {"cover95_pct": _pooled(cov, n), "cover95_min": min(c for c in cov if c is not None),
            "cover95_max": max(c for c in cov if c is not None), "nees": _pooled([s.nees for s in sc], n),
            "sharpness": top / bottom if top is not None and bottom else None,
            "yaw_mag": _pooled([s.yaw_cover95_mag_pct for s in sc], [float(s.n_yaw_mag or 0) for s in sc]),
            "yaw_held": _pooled([s.yaw_cover95_held_pct for s in sc], [float(s.n_yaw_held or 0) for s in sc]),
            "yaw_nees": _pooled([s.yaw_nees for s in sc], ny)}


def pooled_histogram(grp: Sequence[ResultRow]) -> tuple[np.ndarray, np.ndarray] | None:
    """The rows' σ histograms added up (samples, error sums per bin of :data:`BINS`), or None when a row has none."""
    n = np.zeros(len(BINS) + 1)
    e = np.zeros(len(BINS) + 1)
    for r in grp:
        h = r.score.sigma_hist
        if not h:
            return None
        n[h["lo"]: h["lo"] + len(h["n"])] += h["n"]
        e[h["lo"]: h["lo"] + len(h["n"])] += h["e_deg"]
    return n, e


def uncertainty_rows(rows: Sequence[ResultRow]) -> list[list[str]]:
    """Cells of the uncertainty table: per estimator × scenario × perturbation × rate of the rows that carry one."""
    scored = [r for r in rows if r.score.cover95_pct is not None]
    keys = dict.fromkeys((r.estimator, r.scenario, r.perturbation, r.rate) for r in scored)
    out = []
    for key in keys:
        grp = [r for r in scored if (r.estimator, r.scenario, r.perturbation, r.rate) == key]
        g = group_scores(grp)
        f = _formatter(g)
        out.append([key[1], key[2], rate_label(key[3]), key[0], str(len(grp)), f("cover95_pct"),
                    f"{f('cover95_min')}–{f('cover95_max')}", f("nees", ".2f"), f("sharpness", ".2f"),
                    f("yaw_mag"), f("yaw_held"), f("yaw_nees", ".2f")])
    return out


def _formatter(g: dict[str, float | None]) -> Callable[..., str]:
    def f(k: str, fmt: str = ".1f") -> str:
        v = g[k]
        return "–" if v is None else format(v, fmt)

    return f


def reference_text(reference_sd_deg: float) -> str:
    """What the scores take as the reference's own error (``--reference-sd``), for the tables' headings."""
    return f"reference σ {reference_sd_deg:g}° per axis added, --reference-sd"


def reference_line(reference_sd_deg: float) -> str:
    """report.md's line on the reference's own error the coverage and NEES are scored with."""
    return (f"Coverage and NEES (inclination and heading) against σ² = σ_estimator² + σ_ref² per axis, with the "
            f"reference's own error σ_ref = {reference_sd_deg:g}° (`--reference-sd`; 0: the reference taken as exact; "
            "an optical reference's marker and alignment error is no estimator's). Sharpness and the plot use the "
            "estimator's own σ.")


def format_uncertainty_table(rows: Sequence[ResultRow], markdown_table: bool = False,
                             reference_sd_deg: float = 0.0) -> str:
    """The uncertainty table (empty string when no run reported a σ), and where the rows hold more than one dataset
    the table per dataset (:func:`format_dataset_table`); ``reference_sd_deg``: the run's ``--reference-sd``, named
    in the heading of the printed table (report.md says it in :func:`reference_line`)."""
    cells = uncertainty_rows(rows)
    if not cells:
        return ""
    per_dataset = format_dataset_table(rows, markdown_table)
    if markdown_table:
        return "\n".join(["| " + " | ".join(TABLE_HEADERS) + " |", "|---|---|---:|---|" + "---:|" * 8]
                         + ["| " + " | ".join(c) + " |" for c in cells] + (["", per_dataset] if per_dataset else []))
    return "\n".join([f"uncertainty (the σ each estimator reports; {reference_text(reference_sd_deg)}): 95 % "
                      "coverage, NEES per DOF, sharpness", *aligned(TABLE_HEADERS, cells),
                      *(["", per_dataset] if per_dataset else [])])


def dataset_rows(rows: Sequence[ResultRow]) -> list[list[str]]:
    """Cells of the table per dataset: per dataset × sensors (6D/9D) × estimator, coverage and NEES pooled over the
    scored samples of all its rows (every scenario, perturbation and rate), and how many sequences; empty when the
    rows with a σ hold only one dataset × sensors."""
    scored = [r for r in rows if r.score.cover95_pct is not None]
    keys = dict.fromkeys((r.dataset, r.sensors, r.estimator) for r in scored)
    if len({k[:2] for k in keys}) < 2:
        return []
    out = []
    for key in keys:
        grp = [r for r in scored if (r.dataset, r.sensors, r.estimator) == key]
        n = [float(r.score.n_scored) for r in grp]
        f = _formatter({"cover": _pooled([r.score.cover95_pct for r in grp], n),
                        "nees": _pooled([r.score.nees for r in grp], n)})
        out.append([key[0], key[1], key[2], str(len({r.sequence for r in grp})), f("cover"), f("nees", ".2f")])
    return out


def format_dataset_table(rows: Sequence[ResultRow], markdown_table: bool = False) -> str:
    """The inclination's coverage and NEES per dataset × sensors × estimator (:func:`dataset_rows`); empty string
    with one dataset: a σ that holds on one sensor may not on another, and each dataset has its own reference."""
    cells = dataset_rows(rows)
    if not cells:
        return ""
    title = "uncertainty per dataset: 95 % coverage and NEES per DOF pooled over its sequences, scenarios, " \
            "perturbations and rates"
    if markdown_table:
        return "\n".join([title[0].upper() + title[1:] + ":", "", "| " + " | ".join(DATASET_HEADERS) + " |",
                          "|---|---|---|---:|---:|---:|"] + ["| " + " | ".join(c) + " |" for c in cells])
    return "\n".join([title, *aligned(DATASET_HEADERS, cells)])


def format_uncertainty_comparison(pairs: Sequence[tuple[ResultRow, ResultRow]]) -> list[str]:
    """``--compare``'s uncertainty lines: the pairs of rows ``--compare`` matched (A, B on the same sequence) where
    both sides scored a σ, grouped by A's estimator × scenario × perturbation × rate: coverage, NEES and sharpness
    of A and B (no lines when none; older results.json files have no σ scores)."""
    both = [(ra, rb) for ra, rb in pairs if ra.score.cover95_pct is not None and rb.score.cover95_pct is not None]
    if not both:
        return []
    groups = dict.fromkeys((ra.estimator, ra.scenario, ra.perturbation, ra.rate) for ra, _ in both)
    headers = ["estimator", "scenario", "perturbation", "n", "cover95 % A", "B", "NEES A", "B", "sharpness A", "B"]
    rows = []
    for g in groups:
        sel = [(ra, rb) for ra, rb in both if (ra.estimator, ra.scenario, ra.perturbation, ra.rate) == g]
        sa, sb = group_scores([ra for ra, _ in sel]), group_scores([rb for _, rb in sel])
        fa, fb = _formatter(sa), _formatter(sb)
        rows.append([g[0], g[1], g[2], str(len(sel)), fa("cover95_pct"), fb("cover95_pct"), fa("nees", ".2f"),
                     fb("nees", ".2f"), fa("sharpness", ".2f"), fb("sharpness", ".2f")])
    return ["", "uncertainty (the σ each estimator reports): 95 % coverage, NEES per DOF, sharpness; A and B",
            *aligned(headers, rows)]


def plot_error_vs_sigma(rows: Sequence[ResultRow], out_dir: Path, stem: str = "error_vs_sigma",
                        min_samples: int = 50) -> list[Path]:
    """Mean inclination error against the predicted σ_i per estimator (the σ histogram pooled over the sequences;
    bins with at least ``min_samples``), one panel per perturbation, native rate, first scenario; the line of a
    calibrated σ (the mean of a 2-D Gaussian error's length, σ·√(π/2)). Nothing when no row has a σ."""
    rows = [r for r in rows if r.score.sigma_hist and not r.resampled]
    if not rows:
        return []
    scenario = rows[0].scenario
    rows = [r for r in rows if r.scenario == scenario]
    prts = list(dict.fromkeys(r.perturbation for r in rows))
    ests = list(dict.fromkeys(r.estimator for r in rows))
    plt = pl._plt()
    fig, axes = plt.subplots(1, len(prts), figsize=(4.6 * len(prts), 4.0), squeeze=False)
    centres = np.degrees(np.sqrt(BINS[:-1] * BINS[1:]))
    for ax, prt in zip(axes[0], prts, strict=True):
        for est in ests:
            hist = pooled_histogram([r for r in rows if r.perturbation == prt and r.estimator == est])
            if hist is None:
                continue
            n, e = hist
            ok = n[1:-1] >= min_samples
            if ok.any():
                ax.plot(centres[ok], e[1:-1][ok] / n[1:-1][ok], "o-", ms=3, label=est)
        lim = np.array([0.05, 30.0])
        ax.plot(lim, lim * math.sqrt(math.pi / 2.0), "k--", lw=1, label="calibrated: σ·√(π/2)")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("predicted σ_i per axis (°)")
        ax.set_ylabel("mean e_α (°)")
        ax.set_title(f"{scenario}, {prt}")
        ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    pl._fig_legend(fig, axes[0, 0], min(len(ests) + 1, 5))
    return pl._save(fig, out_dir, stem)
