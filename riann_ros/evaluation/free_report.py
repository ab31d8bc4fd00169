"""What ``riann-bag-eval`` shows of inputs without a reference, as text or markdown (ROS-free; used by
:mod:`~riann_ros.evaluation.report` and the CLI): which inputs had one, the estimators' pairwise agreement
(:mod:`~riann_ros.evaluation.agreement`), the gyro bias each estimator settled on beside the stream's rests, and the
stream's health (:mod:`~riann_ros.evaluation.health`).

What a run without a reference can tell: whether the estimators agree and where they part, whether the stream is
regular, complete and in plausible units, and whether an estimator's bias estimate matches the gyro at rest. What
it cannot: which estimator is right where they disagree, or an error that they share.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from riann_ros.evaluation.aggregate import rate_label
from riann_ros.evaluation.perturb import NONE
from riann_ros.evaluation.results import ResultRow, SequenceResult
from riann_ros.evaluation.seq_tables import aligned

NOTE = ("Without a reference nothing is scored. What such an input shows: whether the estimators agree (their "
        "inclination difference; where they part most), the gyro bias each settled on beside the gyro's mean over the "
        "stream's rests (which at rest is the bias), and the stream's health. What it cannot show: which estimator is "
        "right where they differ, or an error they share.")


def which_is_which(results: Sequence[SequenceResult]) -> str:
    """One line naming the inputs scored against a reference and those without one (empty when all have one)."""
    done = [r for r in results if not r.error]
    free = [r.name for r in done if not r.has_reference]
    if not free:
        return ""
    scored = [r.name for r in done if r.has_reference]
    return (f"with a reference (scored): {', '.join(scored) or 'none'}; without a reference (agreement, bias, health "
            f"only): {', '.join(free)}")


def _num(v: Any, fmt: str = ".2f") -> str:
    return "–" if v is None or not math.isfinite(float(v)) else format(float(v), fmt)


def _table(title: str, headers: list[str], cells: list[list[str]], markdown_table: bool) -> str:
    if not cells:
        return ""
    if markdown_table:
        return "\n".join([title + ":", "", "| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
                         + ["| " + " | ".join(c) + " |" for c in cells])
    return "\n".join([title, *(line.rstrip() for line in aligned(headers, cells))])


def format_agreement(results: Sequence[SequenceResult], markdown_table: bool = False) -> str:
    """Per input without a reference and pair of estimators: RMS, mean and max inclination difference, the time of
    the max and the windows where the pair parts most."""
    pairs = [(r.name, p) for r in results if not r.error for p in r.agreement]
    prt = len({p["perturbation"] for _, p in pairs}) > 1 or any(p["perturbation"] != NONE for _, p in pairs)
    multi = len({str(p["rate"]) for _, p in pairs}) > 1
    headers = ["sequence", *(["perturbation"] if prt else []), *(["rate"] if multi else []), "estimators", "n",
               "rms", "mean", "max", "max at s", "where they part most (window s: rms)"]
    cells = []
    for name, p in pairs:
        parts = ", ".join(f"{w['start_s']:g}–{w['end_s']:g}: {w['rms_deg']:.2f}" for w in p["parts"])
        cells.append([name, *([p["perturbation"]] if prt else []), *([rate_label(p["rate"])] if multi else []),
                      f"{p['a']} – {p['b']}", str(p["n"]), _num(p["rms_deg"]), _num(p["mean_deg"]),
                      _num(p["max_deg"]), _num(p["t_max_s"], ".1f"), parts or "–"])
    return _table("agreement without a reference: inclination difference between estimators (°), as recorded",
                  headers, cells, markdown_table)


def _rest_text(health: dict[str, Any] | None) -> str:
    rests = (health or {}).get("rests") or []
    if not rests:
        return "no rest"
    last = rests[-1]
    g = ", ".join(f"{v:.3f}" for v in last["gyr_mean_dps"])
    return f"{len(rests)} rest(s); the last, {last['start_s']:.1f}–{last['end_s']:.1f} s: {g}"


def format_bias(results: Sequence[SequenceResult], rows: Sequence[ResultRow], markdown_table: bool = False) -> str:
    """Per input without a reference: the gyro bias (°/s, x, y, z) each estimator reported at the end of the
    recording as it is, and the mean gyro over the stream's last rest (at rest the gyro measures its bias)."""
    free = {r.name: r for r in results if not r.error and not r.has_reference}
    headers = ["sequence", "estimator", "gyro bias estimate x, y, z (°/s)", "mean gyro at rest (°/s)"]
    cells = []
    for row in rows:
        res = free.get(row.sequence)
        if res is None or row.perturbation != NONE or row.resampled:
            continue
        bias = row.stats.gyro_bias_dps
        cells.append([row.sequence, row.estimator, "–" if bias is None else ", ".join(f"{v:.3f}" for v in bias),
                      _rest_text(res.health)])
    return _table("gyro bias each estimator settled on (none: it reports none), beside the gyro at rest", headers,
                  cells, markdown_table)


def _counts(d: dict[str, int]) -> str:
    return ", ".join(f"{k} {v}" for k, v in d.items()) or "–"


def monitor_trips(r: SequenceResult) -> dict[str, int]:
    """Per monitor of the stream (riann_ros.monitors), the most trips of any estimator's run of the input as it is
    (perturbation none): the monitors test the input, which every estimator is fed alike."""
    out: dict[str, int] = {}
    for row in r.rows:
        if row.perturbation == NONE:
            for k, v in row.stats.monitor_trips.items():
                out[k] = max(out.get(k, 0), v)
    return out


def format_health(results: Sequence[SequenceResult], markdown_table: bool = False, every: bool = False) -> str:
    """The stream's health of the inputs without a reference (``every``: of every input), one row each; unit
    warnings and findings below the table."""
    chosen = [r for r in results if not r.error and r.health and (every or not r.has_reference)]
    headers = ["sequence", "rate Hz", "step std ms", "step min–max ms", "holes", "samples missing",
               "longest hole s", "rejected", "restarts", "monitor trips"]
    cells = []
    notes = []
    for r in chosen:
        h = r.health or {}
        cells.append([r.name, _num(h["rate_hz"], ".3f"), _num(h["step_std_ms"], ".3f"),
                      f"{_num(h['step_min_ms'], '.3f')}–{_num(h['step_max_ms'], '.3f')}", str(h["holes"]),
                      str(h["samples_missing"]), _num(h["longest_hole_s"], ".3f"), _counts(h["rejected"]),
                      _counts(h["restarts"]), _counts(monitor_trips(r))])
        notes += [f"{r.name}: {w}" for w in [*h["warnings"], *h["unit_findings"]]]
    table = _table("stream health (the IMU stream as recorded; the nodes' input gate at its rate)", headers, cells,
                   markdown_table)
    if not table:
        return ""
    bullet = "- " if markdown_table else "health: "
    return "\n".join([table, *([""] if notes and markdown_table else []), *(bullet + n for n in notes)])
