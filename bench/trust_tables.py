"""The tables of BENCHMARKS.md's "Never confidently wrong" section, from committed results (docs/results/lag.json,
nocal.json; bench/results_tables.py writes them into the pages): a late magnetometer and a wrong calibration with
the calibration switched off, scored by heading RMSE and by whether the heading σ covers the error.

Imported by bench/results_tables.py (its :data:`TABLES` holds these); the rows come from its :func:`load`.
"""

from __future__ import annotations

from collections.abc import Callable
from types import SimpleNamespace
from typing import Any

ESTIMATORS = ("riann", "vqf", "madgwick", "mahony")
NAMES = {"riann": "RIANN", "vqf": "VQF", "madgwick": "Madgwick", "mahony": "Mahony"}
LAGS = {"magnetic:lag:100ms": "100 ms", "magnetic:lag:200ms": "200 ms", "magnetic:lag:300ms": "300 ms"}
#: the issue's acceptance: heading within this factor of the recorded field's figure, or the σ covers
#: (coverage while the field is used at least COVER_MIN %, NEES at most NEES_MAX)
RATIO_MAX, COVER_MIN, NEES_MAX = 1.5, 85.0, 2.0


def _heading_scores(rows: Any) -> dict[str, float | None]:
    """Pooled heading coverage (field used) and NEES over the rows (the evaluator's own pooling)."""
    from riann_ros.evaluation.scoring import Score
    from riann_ros.evaluation.uncertainty_report import group_scores

    fields = ("nees", "cover95_pct", "err_bottom_decile_deg", "err_top_decile_deg", "yaw_nees",
              "yaw_cover95_mag_pct", "yaw_cover95_held_pct", "n_yaw_mag", "n_yaw_held", "sigma_hist")
    grp = [SimpleNamespace(score=Score(n_samples=r["n_scored"], n_scored=r["n_scored"], n_unestimated=0,
                                       rmse_deg=r["rmse_deg"], max_err_deg=float("nan"),
                                       **{k: r.get(k) for k in fields}))
           for r in rows.rows]
    return group_scores(grp)


def _every_heading(g: dict[str, float | None], rows: Any) -> float:
    """Pooled coverage over every heading sample, field used and held (the evaluator splits the classical filters'
    samples by their σ, so a σ a monitor widened lands in "held")."""
    n_mag, n_held = sum(r["n_yaw_mag"] or 0 for r in rows.rows), sum(r["n_yaw_held"] or 0 for r in rows.rows)
    return ((g["yaw_mag"] or 0.0) * n_mag + (g["yaw_held"] or 0.0) * n_held) / max(n_mag + n_held, 1)


def _fmt(v: float | None, digits: int = 1) -> str:
    return "–" if v is None else f"{v:.{digits}f}"


def lag_table(load: Callable[[str], Any]) -> str:
    """Per estimator and lag: heading RMSE mean / worst, the ratio of its mean to the recorded field's, the heading
    σ's pooled 95 % coverage while the field is used and over every heading sample, its NEES, and whether the
    acceptance holds."""
    rows = load("lag").where(sensors="9D")
    body = []
    for est in ESTIMATORS:
        base = rows.where(perturbation="none")
        base_mean = base.mean(est, "heading_rmse_deg")
        for cond, label in {"none": "recorded field", **LAGS}.items():
            r = rows.where(perturbation=cond)
            mine = r.where(estimator=est)
            g = _heading_scores(mine)
            ratio = r.mean(est, "heading_rmse_deg") / base_mean
            ok = ratio <= RATIO_MAX or ((g["yaw_mag"] or 0.0) >= COVER_MIN and (g["yaw_nees"] or 0.0) <= NEES_MAX)
            body.append([NAMES[est], label, r.mean_max(est, "heading_rmse_deg"), f"{ratio:.2f}", _fmt(g["yaw_mag"]),
                         _fmt(_every_heading(g, mine)), _fmt(g["yaw_nees"], 2),
                         "" if cond == "none" else ("yes" if ok else "**no**")])
    return _table(["estimator", "magnetometer", "heading mean / worst °", "÷ recorded field",
                   "coverage 95 %, field used", "every heading", "NEES", "accepted"], body, left=2)


def nocal_table(load: Callable[[str], Any]) -> str:
    """``mag_calibration=false`` with a 20, 0, −10 µT hard iron left in the field: heading RMSE, the heading σ's
    pooled coverage and NEES."""
    rows = load("nocal").where(sensors="9D", perturbation="magnetic:offset:20,0,-10")
    body = []
    for est in ESTIMATORS:
        label = f"{est}(mag_calibration=False)"  # the evaluator's label of the spec
        mine = rows.where(estimator=label)
        g = _heading_scores(mine)
        both = _every_heading(g, mine)
        body.append([NAMES[est], rows.mean_max(label, "heading_rmse_deg"), _fmt(both), _fmt(g["yaw_mag"]),
                     _fmt(g["yaw_held"]), _fmt(g["yaw_nees"], 2), "yes" if both >= COVER_MIN else "**no**"])
    return _table(["estimator (`mag_calibration=false`)", "heading mean / worst °", "coverage 95 %, every heading",
                   "field used", "held", "NEES", "coverage ≥ 85 %"], body)


def recorded_table(load: Callable[[str], Any]) -> str:
    """The recorded field (9D, lag.json's ``none``) against the committed figures of the code before the monitors
    (mag9d.json): per estimator the largest per-trial change of the heading and the inclination RMSE."""
    now = load("lag").where(sensors="9D", perturbation="none")
    before = load("mag9d").where(sensors="9D")
    body = []
    for est in ESTIMATORS:
        b = {r["sequence"]: r for r in before.rows if r["estimator"] == est}
        d_head = [r["heading_rmse_deg"] - b[r["sequence"]]["heading_rmse_deg"] for r in now.rows
                  if r["estimator"] == est and r["sequence"] in b]
        d_inc = [r["rmse_deg"] - b[r["sequence"]]["rmse_deg"] for r in now.rows
                 if r["estimator"] == est and r["sequence"] in b]
        body.append([NAMES[est], now.mean_max(est, "heading_rmse_deg"), before.mean_max(est, "heading_rmse_deg"),
                     f"{max(d_head):+.3f}", f"{max(d_inc):+.3f}"])
    return _table(["estimator (9D, recorded field)", "heading mean / worst °", "mag9d.json", "largest heading change",
                   "largest inclination change"], body)


def _table(header: list[str], body: list[list[str]], left: int = 1) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * left + "---:|" * (len(header) - left)]
    return "\n".join(lines + ["| " + " | ".join(row) + " |" for row in body])
