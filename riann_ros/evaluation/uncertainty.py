"""Scoring the uncertainty an estimator reports beside its estimate (ROS-free).

Per scored sample the estimator's σ (rad): ``σ_i`` of the inclination per horizontal axis and ``σ_ψ`` of the
heading (:meth:`riann_ros.estimators.base.AttitudeEstimator.sigma`). The inclination error ``e_α`` (paper eq. 3) is
the length of the 2-D error of roll and pitch, so for a calibrated ``σ_i`` ``e_α²/σ_i²`` is χ² with 2 degrees of
freedom:

* NEES per degree of freedom: the mean of ``e_α² / (2 σ_i²)`` (1 when calibrated; > 1 overconfident);
* coverage of the 95 % region: the share of samples with ``e_α²/σ_i² ≤ χ²₂(0.95) = 5.991`` (95 % when calibrated);
* sharpness: the mean ``e_α`` of the samples in the top decile of ``σ_i`` over that of the bottom decile (deciles
  from a histogram of σ in :data:`BINS`, so a bag of any length is scored in bounded memory).

The heading the same way with one degree of freedom (``χ²₁(0.95) = 3.841``), on samples whose ``σ_ψ`` is below the
unobservable 180°, split into those corrected by a field (``σ_ψ`` at the field's σ) and those held by the gyro
after one (larger). Samples without a σ (NaN) are not counted.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from riann_ros.defaults import MAG_HEADING_SD_DEG, YAW_FREE_SD_DEG

if TYPE_CHECKING:
    from pathlib import Path

    from riann_ros.evaluation.results import ResultRow

CHI2_2_95 = 5.991  # χ²₂(0.95)
CHI2_1_95 = 3.841  # χ²₁(0.95)
BINS = np.radians(np.logspace(-3, math.log10(180.0), 161))  # σ_i bin edges (rad), 0.001° … 180°
MAG_SD = math.radians(MAG_HEADING_SD_DEG) * (1.0 + 1e-9)
FREE_SD = math.radians(YAW_FREE_SD_DEG) * (1.0 - 1e-9)
KEYS = ("nees", "cover95_pct", "err_bottom_decile_deg", "err_top_decile_deg", "yaw_nees", "yaw_cover95_mag_pct",
        "yaw_cover95_held_pct", "n_yaw_mag", "n_yaw_held")


class UncertaintySums:
    """Running sums of the uncertainty scores of one scenario × estimator run."""

    def __init__(self) -> None:
        self.n = self.inside = 0
        self.nees = 0.0
        self.hist_n = np.zeros(len(BINS) + 1)
        self.hist_e = np.zeros(len(BINS) + 1)
        self.yaw = {"mag": [0, 0], "held": [0, 0]}  # [samples, inside the 95 % region]
        self.yaw_nees = 0.0

    def add(self, e: NDArray[np.float64], e_yaw: NDArray[np.float64], sigma: NDArray[np.float64]) -> None:
        """Scored samples: inclination and heading errors (rad) and their σ (n, 2) (NaN rows: none reported)."""
        ok = np.isfinite(sigma).all(axis=1) & (sigma[:, 0] > 0.0)
        if not ok.any():
            return
        e, ey, s = e[ok], e_yaw[ok], sigma[ok]
        r = (e / s[:, 0]) ** 2
        self.n += len(r)
        self.inside += int(np.sum(r <= CHI2_2_95))
        self.nees += float(np.sum(r)) / 2.0
        b = np.searchsorted(BINS, s[:, 0])
        self.hist_n += np.bincount(b, minlength=len(self.hist_n))
        self.hist_e += np.bincount(b, weights=e, minlength=len(self.hist_e))
        held = (s[:, 1] > MAG_SD) & (s[:, 1] < FREE_SD)
        for key, sel in (("mag", s[:, 1] <= MAG_SD), ("held", held)):
            if sel.any():
                ry = (ey[sel] / s[sel, 1]) ** 2
                self.yaw[key][0] += int(sel.sum())
                self.yaw[key][1] += int(np.sum(ry <= CHI2_1_95))
                self.yaw_nees += float(np.sum(ry))

    def result(self) -> dict[str, Any]:
        """The scores (None where no sample had a σ); keys :data:`KEYS` and ``sigma_hist`` (:func:`histogram`)."""
        if self.n == 0:
            return {**dict.fromkeys(KEYS), "sigma_hist": None}
        bottom, top = decile_errors(self.hist_n, self.hist_e)
        ny = self.yaw["mag"][0] + self.yaw["held"][0]

        def pct(k: str) -> float | None:
            n, inside = self.yaw[k]
            return 100.0 * inside / n if n else None

        return {"nees": self.nees / self.n, "cover95_pct": 100.0 * self.inside / self.n,
                "err_bottom_decile_deg": math.degrees(bottom), "err_top_decile_deg": math.degrees(top),
                "yaw_nees": self.yaw_nees / ny if ny else None, "yaw_cover95_mag_pct": pct("mag"),
                "yaw_cover95_held_pct": pct("held"), "n_yaw_mag": self.yaw["mag"][0],
                "n_yaw_held": self.yaw["held"][0], "sigma_hist": histogram(self.hist_n, self.hist_e)}


def histogram(hist_n: NDArray[np.float64], hist_e: NDArray[np.float64]) -> dict[str, Any]:
    """The σ_i histogram as results.json keeps it: the first non-empty bin ``lo`` of :data:`BINS` (bin ``k`` holds
    σ below ``BINS[k]``), then per bin the samples ``n`` and the sum of their errors ``e_deg``."""
    nz = np.flatnonzero(hist_n)
    lo, hi = int(nz[0]), int(nz[-1]) + 1
    return {"lo": lo, "n": [int(v) for v in hist_n[lo:hi]], "e_deg": [round(math.degrees(v), 6) for v in hist_e[lo:hi]]}


def decile_errors(hist_n: NDArray[np.float64], hist_e: NDArray[np.float64]) -> tuple[float, float]:
    """The mean error of the samples in the bottom and in the top decile of σ, from per-bin counts and error sums
    (a bin split at the decile counts in proportion)."""
    total = float(hist_n.sum())
    k = 0.1 * total

    def lowest(n: NDArray[np.float64], s: NDArray[np.float64]) -> float:
        c = np.cumsum(n)
        full = c <= k
        take = float(s[full].sum())
        j = int(np.argmax(~full)) if (~full).any() else len(n)
        rest = k - (float(c[j - 1]) if j else 0.0)
        if j < len(n) and n[j] > 0:
            take += s[j] * rest / n[j]
        return take / k

    return lowest(hist_n, hist_e), lowest(hist_n[::-1], hist_e[::-1])


# -- tables ------------------------------------------------------------------------------------------------------
NOTE = ("Roll and pitch errors as a 2-D Gaussian with the reported σ per axis: the share of scored samples inside the "
        "95 % region (e²/σ² ≤ 5.991; pooled, and the range over the sequences), the mean NEES per degree of freedom "
        "(1 when calibrated), and the mean error in each sequence's top decile of σ over its bottom decile's. The "
        "heading (1 DOF, 3.841) on samples whose σ is below 180°: while a field corrects it, and while it is held by "
        "the gyro after one. Madgwick, Mahony and VQF report constants (2°; heading 180°, 5° with a field).")
TABLE_HEADERS = ["scenario", "perturbation", "rate", "estimator", "n", "cover95 %", "cover95 min–max %", "NEES/DOF",
                 "err top/bottom σ decile", "yaw cover95 % field used", "yaw cover95 % held", "yaw NEES"]


def _pooled(values: list[float | None], weights: list[float]) -> float | None:
    pairs = [(v, w) for v, w in zip(values, weights, strict=True) if v is not None and w > 0]
    total = sum(w for _, w in pairs)
    return sum(v * w for v, w in pairs) / total if total else None


def group_scores(grp: Sequence[ResultRow]) -> dict[str, float | None]:
    """The uncertainty scores of a group of rows (one estimator × scenario × perturbation × rate over sequences):
    coverage and NEES pooled over their scored samples, coverage's range over the sequences, sharpness as the mean
    error of each sequence's top decile of σ over that of each sequence's bottom decile (pooled), the heading's
    coverage pooled over the samples with the field used and held."""
    sc = [r.score for r in grp]
    n = [float(s.n_scored) for s in sc]
    cov = [s.cover95_pct for s in sc]
    ny = [float((s.n_yaw_mag or 0) + (s.n_yaw_held or 0)) for s in sc]
    top = _pooled([s.err_top_decile_deg for s in sc], n)
    bottom = _pooled([s.err_bottom_decile_deg for s in sc], n)
    return {"cover95_pct": _pooled(cov, n), "cover95_min": min(c for c in cov if c is not None),
            "cover95_max": max(c for c in cov if c is not None), "nees": _pooled([s.nees for s in sc], n),
            "sharpness": top / bottom if top is not None and bottom else None,
            "yaw_mag": _pooled([s.yaw_cover95_mag_pct for s in sc], [float(s.n_yaw_mag or 0) for s in sc]),
            "yaw_held": _pooled([s.yaw_cover95_held_pct for s in sc], [float(s.n_yaw_held or 0) for s in sc]),
            "yaw_nees": _pooled([s.yaw_nees for s in sc], ny)}


def uncertainty_rows(rows: Sequence[ResultRow]) -> list[list[str]]:
    """Cells of the uncertainty table: per estimator × scenario × perturbation × rate of the rows that carry one."""
    from riann_ros.evaluation.aggregate import rate_label  # here: results imports this module

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


def format_uncertainty_table(rows: Sequence[ResultRow], markdown_table: bool = False) -> str:
    """The uncertainty table (empty string when no run reported a σ)."""
    cells = uncertainty_rows(rows)
    if not cells:
        return ""
    if markdown_table:
        return "\n".join(["| " + " | ".join(TABLE_HEADERS) + " |", "|---|---|---:|---|" + "---:|" * 8]
                         + ["| " + " | ".join(c) + " |" for c in cells])
    widths = [max(len(h), *(len(c[i]) for c in cells)) for i, h in enumerate(TABLE_HEADERS)]
    lines = ["uncertainty (the σ each estimator reports): 95 % coverage, NEES per DOF, sharpness",
             "  ".join(h.ljust(w) for h, w in zip(TABLE_HEADERS, widths, strict=True))]
    lines += ["  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)) for row in cells]
    return "\n".join(lines)


def format_uncertainty_comparison(a: Sequence[ResultRow], b: Sequence[ResultRow]) -> list[str]:
    """``--compare``'s uncertainty lines: per estimator × scenario × perturbation × rate, over the sequences both runs
    scored with a σ, coverage, NEES and sharpness of A and B (no lines when none; older results.json files have no
    σ scores)."""
    def k(r: ResultRow) -> tuple[str, str, str, str | float, str]:
        return (r.sequence, r.scenario, r.perturbation, r.rate, r.estimator)

    ra = {k(r): r for r in a if r.score.cover95_pct is not None}
    rb = {k(r): r for r in b if r.score.cover95_pct is not None}
    both = [key for key in ra if key in rb]
    if not both:
        return []
    groups = dict.fromkeys((key[4], key[1], key[2], key[3]) for key in both)
    headers = ["estimator", "scenario", "perturbation", "n", "cover95 % A", "B", "NEES A", "B", "sharpness A", "B"]
    rows = []
    for g in groups:
        keys = [key for key in both if (key[4], key[1], key[2], key[3]) == g]
        sa, sb = group_scores([ra[x] for x in keys]), group_scores([rb[x] for x in keys])
        fa, fb = _formatter(sa), _formatter(sb)
        rows.append([g[0], g[1], g[2], str(len(keys)), fa("cover95_pct"), fb("cover95_pct"), fa("nees", ".2f"),
                     fb("nees", ".2f"), fa("sharpness", ".2f"), fb("sharpness", ".2f")])
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(headers)]
    return ["", "uncertainty (the σ each estimator reports): 95 % coverage, NEES per DOF, sharpness; A and B",
            "  ".join(h.ljust(w) for h, w in zip(headers, widths, strict=True)),
            *("  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)) for r in rows)]


def plot_error_vs_sigma(rows: Sequence[ResultRow], out_dir: Path, stem: str = "error_vs_sigma",
                        min_samples: int = 50) -> list[Path]:
    """Mean inclination error against the predicted σ_i per estimator (the σ histogram pooled over the sequences;
    bins with at least ``min_samples``), one panel per perturbation, native rate, first scenario; the line of a
    calibrated σ (the mean of a 2-D Gaussian error's length, σ·√(π/2)). Nothing when no row has a σ."""
    from riann_ros.evaluation import plots as pl  # here: plots imports results, which imports this module

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
            n = np.zeros(len(BINS) + 1)
            e = np.zeros(len(BINS) + 1)
            for r in rows:
                h = r.score.sigma_hist
                if r.perturbation == prt and r.estimator == est and h:
                    n[h["lo"]: h["lo"] + len(h["n"])] += h["n"]
                    e[h["lo"]: h["lo"] + len(h["n"])] += h["e_deg"]
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
