"""Tables, files and plots of ``riann-bag-eval`` results (ROS-free; matplotlib with the Agg backend)."""

from __future__ import annotations

import csv
import json
import math
import os
import platform
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from riann_ros.evaluation import ALL_DATASETS, NATIVE, SCENARIOS, rate_order

CSV_FIELDS = (
    "sequence",
    "dataset",
    "scenario",
    "rate",
    "rate_hz",
    "estimator",
    "rmse_deg",
    "max_err_deg",
    "heading_rmse_deg",
    "total_rmse_deg",
    "n_samples",
    "n_scored",
    "n_unestimated",
    "seconds",
    "cpu_seconds",
    "mode",
    "published",
    "received",
    "lost",
    "source",
)


# ---------------------------------------------------------------------------------------------------
# terminal
# ---------------------------------------------------------------------------------------------------
class Progress:
    """A one-line progress bar on stderr (plain lines when stderr is not a terminal)."""

    def __init__(self, total: int, stream=None, width: int = 30, enabled: bool = True) -> None:
        self.total = max(total, 1)
        self.stream = stream or sys.stderr
        self.width = width
        self.enabled = enabled
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())

    def __call__(self, done: int, total: int, result: Any = None) -> None:
        if not self.enabled:
            return
        name = getattr(result, "name", "") or Path(getattr(result, "source", "")).name
        status = "FAILED" if getattr(result, "error", None) else f"{getattr(result, 'seconds', 0.0):.1f}s"
        filled = int(self.width * done / self.total)
        bar = "#" * filled + "-" * (self.width - filled)
        line = f"[{bar}] {done}/{total} {name} ({status})"
        if self.tty:
            self.stream.write("\r\033[K" + line + ("\n" if done >= total else ""))
        else:
            self.stream.write(line + "\n")
        self.stream.flush()


def _rate_label(rate: str | float) -> str:
    return rate if rate == NATIVE else f"{float(rate):g}"


def format_table(agg: Sequence[dict[str, Any]], title: str = "attitude RMSE e_α (°) per sequence") -> str:
    """Estimator × scenario × dataset (× rate when several): n, mean / median / max RMSE."""
    if not agg:
        return "(no results)"
    rates = {a["rate"] for a in agg}
    headers = [
        "scenario",
        "dataset",
        *(["rate"] if len(rates) > 1 else []),
        "estimator",
        "n",
        "mean",
        "median",
        "max",
    ]
    lines = []
    for a in agg:
        lines.append(
            [
                a["scenario"],
                a["dataset"],
                *([_rate_label(a["rate"])] if len(rates) > 1 else []),
                a["estimator"],
                str(a["n"]),
                f"{a['mean']:.2f}",
                f"{a['median']:.2f}",
                f"{a['max']:.2f}",
            ]
        )
    widths = [max(len(h), *(len(r[i]) for r in lines)) for i, h in enumerate(headers)]
    numeric = {"n", "mean", "median", "max", "rate"}

    def fmt(row: list[str]) -> str:
        return "  ".join(
            c.rjust(w) if h in numeric else c.ljust(w) for c, w, h in zip(row, widths, headers, strict=True)
        )

    out = [title, fmt(headers), "  ".join("-" * w for w in widths)]
    prev = None
    for row, a in zip(lines, agg, strict=True):
        key = (a["scenario"], a["dataset"], a["rate"])
        if prev is not None and key != prev:
            out.append("")
        prev = key
        out.append(fmt(row))
    return "\n".join(out)


def format_markdown_table(agg: Sequence[dict[str, Any]]) -> str:
    rates = {a["rate"] for a in agg}
    multi = len(rates) > 1
    head = "| scenario | dataset | " + ("rate Hz | " if multi else "") + "estimator | n | mean ° | median ° | max ° |"
    sep = "|---|---|" + ("---:|" if multi else "") + "---|---:|---:|---:|---:|"
    out = [head, sep]
    for a in agg:
        rate = f"{_rate_label(a['rate'])} | " if multi else ""
        out.append(
            f"| {a['scenario']} | {a['dataset']} | {rate}{a['estimator']} | {a['n']} | {a['mean']:.2f} | "
            f"{a['median']:.2f} | {a['max']:.2f} |"
        )
    return "\n".join(out)


# ---------------------------------------------------------------------------------------------------
# files
# ---------------------------------------------------------------------------------------------------
def write_csv(path: Path, rows: Sequence[dict[str, Any]]) -> None:
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(CSV_FIELDS), extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6f}" if isinstance(v, float) else v) for k, v in r.items()})


def versions() -> dict[str, Any]:
    """Package, model and runtime versions for results.json."""
    out: dict[str, Any] = {"python": platform.python_version(), "platform": platform.platform()}
    from importlib import metadata

    for dist in ("riann_ros", "riann", "onnxruntime", "numpy", "scipy", "vqf"):
        try:
            out[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            out[dist] = None
    if out["riann_ros"] is None:
        try:
            from riann_ros import __version__

            out["riann_ros"] = __version__
        except ImportError:
            pass
    try:
        import hashlib

        from riann_ros.estimators.riann import default_model_path

        p = default_model_path()
        out["riann_model"] = {"path": str(p), "sha256": hashlib.sha256(p.read_bytes()).hexdigest()}
    except Exception as exc:
        out["riann_model"] = {"error": str(exc)}
    return out


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


def write_markdown(
    path: Path,
    agg: Sequence[dict[str, Any]],
    rows: Sequence[dict[str, Any]],
    settings: dict[str, Any],
    failures: Sequence[dict[str, str]],
    plots: Sequence[Path],
    tuning: Sequence[dict[str, Any]] = (),
    sources: Sequence[str] = (),
) -> None:
    lines = ["# riann-bag-eval report", ""]
    lines.append(f"Command: `{settings.get('command', '')}`")
    lines.append("")
    lines.append(
        f"Scenarios: {', '.join(settings['scenarios'])}; seed {settings['seed']}; rates: "
        f"{', '.join('native' if r is None else f'{r:g} Hz' for r in settings['rates'])}."
    )
    lines.append(
        "Metric: RMSE of the inclination error e_α (heading ignored, paper eq. 3) over the scored samples "
        "with a reference; table values summarise the per-sequence RMSEs."
    )
    if sources:
        lines += ["", "Data: " + "; ".join(sorted(set(sources)))]
    lines += ["", "## Summary", "", format_markdown_table(agg), ""]
    if tuning:
        lines += ["## Tuning (grid search on these sequences)", ""]
        for t in tuning:
            b = t["best"]
            lines.append(
                f"- {t['estimator']} ({t['scenario']}): best {b['label']} — mean {b['mean']:.2f}°, max {b['max']:.2f}°"
            )
        lines.append("")
    lines += ["## Per sequence", ""]
    ests = list(dict.fromkeys(r["estimator"] for r in rows))
    for scn in [s for s in SCENARIOS if any(r["scenario"] == s for r in rows)]:
        for rate in sorted({r["rate"] for r in rows if r["scenario"] == scn}, key=rate_order):
            lines += [
                f"### {scn}, {_rate_label(rate)}{'' if rate == NATIVE else ' Hz'}",
                "",
                "| sequence | " + " | ".join(ests) + " |",
            ]
            lines.append("|---|" + "---:|" * len(ests))
            seqs = list(dict.fromkeys(r["sequence"] for r in rows if r["scenario"] == scn))
            for seq in seqs:
                cells = []
                for e in ests:
                    v = [
                        r["rmse_deg"]
                        for r in rows
                        if r["sequence"] == seq and r["scenario"] == scn and r["estimator"] == e and r["rate"] == rate
                    ]
                    cells.append(f"{v[0]:.2f}" if v else "–")
                lines.append(f"| {seq} | " + " | ".join(cells) + " |")
            lines.append("")
    if failures:
        lines += ["## Failed inputs", ""] + [f"- {f['error']}" for f in failures] + [""]
    if plots:
        lines += ["## Plots", ""] + [f"![{p.stem}]({p.name})" for p in plots if p.suffix == ".png"] + [""]
    path.write_text("\n".join(lines))


# ---------------------------------------------------------------------------------------------------
# plots
# ---------------------------------------------------------------------------------------------------
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


def plot_boxes(rows: Sequence[dict[str, Any]], out_dir: Path, stem: str = "rmse_boxplots") -> list[Path]:
    """Figure 8 of the paper: RMSE distribution per estimator, one panel per scenario, grouped by dataset
    (native rates only)."""
    plt = _plt()
    rows = [r for r in rows if not r.get("resampled")]
    if not rows:
        return []
    scenarios = [s for s in SCENARIOS if any(r["scenario"] == s for r in rows)]
    datasets = list(dict.fromkeys(r["dataset"] for r in rows))
    ests = list(dict.fromkeys(r["estimator"] for r in rows))
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
                [r["rmse_deg"] for r in rows if r["scenario"] == scn and r["dataset"] == d and r["estimator"] == est]
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
    scenarios = [s for s in SCENARIOS if s in series["curves"]]
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


def plot_rmse_vs_rate(rows: Sequence[dict[str, Any]], out_dir: Path, stem: str = "rmse_vs_rate") -> list[Path]:
    """Figure 9 of the paper: mean RMSE (and min–max band) over all sequences versus sampling rate, per
    estimator and scenario. Only when several rates were evaluated."""
    plt = _plt()
    rows = [r for r in rows if r.get("resampled")]
    rates = sorted({r["rate_hz"] for r in rows})
    if len(rates) < 2:
        return []
    scenarios = [s for s in SCENARIOS if any(r["scenario"] == s for r in rows)]
    ests = list(dict.fromkeys(r["estimator"] for r in rows))
    fig, axes = plt.subplots(1, len(scenarios), figsize=(5.5 * len(scenarios), 3.8), squeeze=False)
    for ax, scn in zip(axes[0], scenarios, strict=True):
        for est in ests:
            vals = [
                [r["rmse_deg"] for r in rows if r["scenario"] == scn and r["estimator"] == est and r["rate_hz"] == f]
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


def dataset_order(agg: Sequence[dict[str, Any]]) -> list[str]:
    ds = list(dict.fromkeys(a["dataset"] for a in agg))
    return [d for d in ds if d != ALL_DATASETS] + ([ALL_DATASETS] if ALL_DATASETS in ds else [])
