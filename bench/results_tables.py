"""The result tables and figures of README.md, docs/results.md, BENCHMARKS.md, docs/riann.md and bags/README.md,
written from committed results.

Usage::

    .venv/bin/python bench/results_tables.py             # rewrite every marked table and figure from docs/results/
    .venv/bin/python bench/results_tables.py --check     # exit 1 when a committed page differs (test_results_tables)
    .venv/bin/python bench/results_tables.py trim NAME RUN/results.json [RUN2/results.json …] --command "…"

``docs/results/*.json`` are ``riann-bag-eval`` results.json files trimmed to what the tables need (``trim``): the
command that made them and per row sequence, scenario, perturbation, rate, estimator, sensors and the RMSEs
(inclination; heading and total for 9D rows). Which run each file comes from is in docs/results/README.md.

In a page, ``<!-- results:NAME -->`` … ``<!-- /results:NAME -->`` holds what :data:`TABLES` writes for NAME: a
table (markers on their own lines) or a figure within a sentence (markers inline). Everything between the markers
is the script's; everything outside them is the author's, who cites only figures the tables show.
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
import sys
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

from evo_example import TABLES as EVO_TABLES  # the evo example of docs/evaluation.md (bench/evo_example.py)
from trust_tables import lag_table, nocal_table, recorded_table  # BENCHMARKS "Never confidently wrong"

from riann_ros.estimators.riann.s1_timeline import SAMPLE_DELAY

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "docs" / "results"
PAGES = ("README.md", "docs/results.md", "BENCHMARKS.md", "docs/riann.md", "bags/README.md", "docs/evaluation.md",
         "docs/consensus.md")
FIELDS = ("sequence", "scenario", "perturbation", "rate", "estimator", "sensors", "rmse_deg", "heading_rmse_deg",
          "total_rmse_deg", "best_t_offset_s", "mag_converged_after_s")
#: the uncertainty scores a file keeps when trimmed with ``--uncertainty`` (riann_ros/evaluation/uncertainty.py)
UNCERTAINTY_FIELDS = ("n_scored", "nees", "cover95_pct", "err_bottom_decile_deg", "err_top_decile_deg", "yaw_nees",
                      "yaw_cover95_mag_pct", "yaw_cover95_held_pct", "n_yaw_mag", "n_yaw_held", "sigma_hist")
ESTIMATORS = ("riann", "vqf", "madgwick", "mahony")
DEMO_ESTIMATORS = ("riann", "consensus", "vqf", "madgwick", "mahony")  # make demo's -e
NAMES = {"riann": "RIANN", "vqf": "VQF", "madgwick": "Madgwick", "mahony": "Mahony", "consensus": "Consensus"}
DROPOUT_TRIALS = ("02", "07", "10", "15", "24", "27")  # the six trials with movement throughout
#: the trials whose motion leaves a hard iron unobservable or mistaken (BROAD's descriptions): 10 and 15 translate
#: without rotation (through the lab's field gradients), 27 barely turns (a vibrating phone) for its first 35 s
MAGCAL_LIMITED = ("10", "15", "27")
MARKER = re.compile(r"<!-- results:(?P<name>[\w-]+) -->(?P<body>.*?)<!-- /results:(?P=name) -->", re.S)


# ---------------------------------------------------------------------------------------------------
# results
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Rows:
    rows: tuple[dict, ...]

    def where(self, **match: object) -> Rows:
        return Rows(tuple(r for r in self.rows if all(r.get(k) == v for k, v in match.items())))

    def trials(self, trials: Iterable[str]) -> Rows:
        keep = tuple(trials)
        return Rows(tuple(r for r in self.rows if r["sequence"][:2] in keep))

    def values(self, estimator: str, field: str = "rmse_deg") -> list[float]:
        return [r[field] for r in self.rows if r["estimator"] == estimator]

    def mean_max(self, estimator: str, field: str = "rmse_deg") -> str:
        v = self.values(estimator, field)
        return f"{sum(v) / len(v):.2f} / {max(v):.2f}" if v else "–"

    def mean(self, estimator: str, field: str = "rmse_deg") -> float:
        v = self.values(estimator, field)
        return sum(v) / len(v)

    def ordered(self, key: str) -> list:
        return list(dict.fromkeys(r[key] for r in self.rows))

    def estimators(self) -> list[str]:
        return self.ordered("estimator")


def load(name: str) -> Rows:
    data = json.loads((RESULTS / f"{name}.json").read_text())
    cols, same = data["columns"], data.get("same", {})
    return Rows(tuple({**same, **dict(zip(cols, row, strict=True))} for row in data["rows"]))


def _rounded(v: object) -> object:
    if isinstance(v, float):
        return round(v, 6)
    if isinstance(v, list):
        return [_rounded(x) for x in v]
    if isinstance(v, dict):
        return {k: _rounded(x) for k, x in v.items()}
    return v


def trim(name: str, sources: list[Path], command: str, uncertainty: bool = False) -> Path:
    """results.json files (of one command, or of runs that together make one) cut down to :data:`FIELDS` (and
    with ``uncertainty`` :data:`UNCERTAINTY_FIELDS`; numbers to 6 decimals) in docs/results/NAME.json, one row per
    line."""
    rows = [{k: _rounded(v) for k, v in r.items()} for src in sources for r in json.loads(src.read_text())["results"]]
    keep = FIELDS + (UNCERTAINTY_FIELDS if uncertainty else ())
    present = [f for f in keep if any(f in r for r in rows)]
    # a field with one value in every row is stored once ("same")
    same = {f: rows[0].get(f) for f in present if len({json.dumps(r.get(f)) for r in rows}) == 1}
    cols = [f for f in present if f not in same]
    out = [[r.get(c) for c in cols] for r in rows]
    text = ('{\n  "command": ' + json.dumps(command, ensure_ascii=False) + ',\n  "same": ' + json.dumps(same)
            + ',\n  "columns": ' + json.dumps(cols) + ',\n  "rows": [\n'
            + ",\n".join("    " + json.dumps(r, ensure_ascii=False) for r in out) + "\n  ]\n}\n")
    dst = RESULTS / f"{name}.json"
    dst.write_text(text)
    return dst


# ---------------------------------------------------------------------------------------------------
# tables
# ---------------------------------------------------------------------------------------------------
def _table(header: list[str], body: list[list[str]], left: int = 1) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * left + "---:|" * (len(header) - left)]
    return "\n".join(lines + ["| " + " | ".join(row) + " |" for row in body])


def conditions_table(rows: Rows, estimators: Iterable[str] = ESTIMATORS) -> str:
    """mean / worst per condition (the perturbations in run order) and estimator."""
    ests = list(estimators)
    return _table(["condition", *ests], [[c, *(rows.where(perturbation=c).mean_max(e) for e in ests)]
                                         for c in rows.ordered("perturbation")])


def perturbed(scenario: str) -> Callable[[], str]:
    return lambda: conditions_table(load("perturbed").where(scenario=scenario))


def dropout_six() -> str:
    rows = load("perturbed").where(scenario="as-recorded").trials(DROPOUT_TRIALS)
    return conditions_table(Rows(tuple(r for r in rows.rows if r["perturbation"] in ("none", "dropout:0.1-0.6s@10s"))))


def rate_ratios() -> str:
    """RIANN per trial at every FFT-resampled rate, with its ratio to the native-rate RMSE."""
    native = {r["sequence"]: r["rmse_deg"] for r in load("perturbed").where(
        scenario="as-recorded", perturbation="none", estimator="riann").rows}
    rated = load("rates").where(estimator="riann")
    rates = sorted(rated.ordered("rate"))
    worst = dict.fromkeys(rates, 0.0)
    body = []
    for seq, base in native.items():
        cells = []
        for f in rates:
            v = rated.where(sequence=seq, rate=f).values("riann")[0]
            worst[f] = max(worst[f], v / base)
            cells.append(f"{v:.2f} ({v / base:.2f}×)")
        body.append([seq[:2], f"{base:.2f}", *cells])
    body.append(["worst ratio", "", *(f"{worst[f]:.2f}×" for f in rates)])
    return _table(["trial", "native °", *(f"{f:g} Hz" for f in rates)], body)


def rates_table(name: str, estimators: Iterable[str]) -> Callable[[], str]:
    def make() -> str:
        rows = load(name)
        ests = list(estimators)
        return _table(["rate", *ests], [[f"{f:g} Hz", *(rows.where(rate=f).mean_max(e) for e in ests)]
                                        for f in sorted(rows.ordered("rate"))])
    return make


STREAMS = (("", "interval means (`rate:HZ`)"), (":points", "point samples (`:points`)"),
           (":lowpass", "MEMS low-pass (`:lowpass`)"))


def sample_delay_table() -> str:
    """Regular streams made three ways at each rate: RIANN at every ``sample_delay`` of the run, and VQF."""
    rows = load("sample_delay")
    delays = sorted((e for e in rows.estimators() if e.startswith("riann")), key=_delay_of)
    rates = _regular_rates(rows)
    head = [f"`sample_delay={_delay_of(e):g}`" + (" (default)" if e == "riann" else "") for e in delays]
    body = [[f"{hz} Hz", label, *(rows.where(perturbation=f"rate:{hz}{suffix}").mean_max(e) for e in [*delays, "vqf"])]
            for hz in rates for suffix, label in STREAMS]
    return _table(["rate", "stream", *head, "VQF"], body, left=2)


def sample_delay_timing() -> str:
    """The median over the trials of the best time offset (ms; + the estimate leads) per rate and stream kind, of
    RIANN at its default and of VQF."""
    rows = load("sample_delay")
    rates = _regular_rates(rows)

    def ms(p: str, est: str) -> str:
        return f"{1e3 * statistics.median(rows.where(perturbation=p).values(est, 'best_t_offset_s')):+.1f}"

    body = [[f"{hz} Hz", *(f"{ms(f'rate:{hz}{sfx}', 'riann')} / {ms(f'rate:{hz}{sfx}', 'vqf')}" for sfx, _ in STREAMS)]
            for hz in rates]
    return _table(["rate", *(label for _, label in STREAMS)], body)


def _regular_rates(rows: Rows) -> list[int]:
    """The rates (Hz) of the ``rate:HZ[:kind]`` conditions in ``rows``."""
    return sorted({int(p.split(":")[1]) for p in rows.ordered("perturbation")})


def _delay_of(estimator: str) -> float:
    """The sample delay of a RIANN spec label (``riann`` is the default's)."""
    m = re.search(r"sample_delay=([\d.]+)", estimator)
    return float(m[1]) if m else SAMPLE_DELAY


def scenarios_table() -> str:
    rows = load("scenarios")
    body = []
    for scn in rows.ordered("scenario"):
        for est in ("riann", "madgwick", "mahony", "vqf"):
            v = rows.where(scenario=scn).values(est)
            body.append([scn, est, f"{sum(v) / len(v):.2f}", f"{statistics.median(v):.2f}", f"{max(v):.2f}"])
    return _table(["scenario", "estimator", "mean °", "median °", "max °"], body, left=2)


def tuned_table() -> str:
    rows = load("tuned")
    body = []
    for est in rows.estimators():
        v = rows.values(est)
        label = f"{est} (never tuned)" if est == "riann" else (est if est.endswith("tuned") else f"{est} (defaults)")
        body.append([label, f"{sum(v) / len(v):.2f}", f"{statistics.median(v):.2f}", f"{max(v):.2f}"])
    return _table(["estimator (realistic)", "mean °", "median °", "max °"], body)


FRONTEND_CONDITIONS = ("none", "jitter:10/20/30ms", "rate:50", "bias:3,3,0", "bias:random:2", "dropout:0.1-0.6s@10s")


def frontend_table() -> str:
    base = fe = load("frontend")
    cols = [(f, s) for s in ("as-recorded", "realistic") for f in ("madgwick", "mahony")]
    body = []
    for c in FRONTEND_CONDITIONS:
        cells = [f"{base.where(scenario=s, perturbation=c).mean_max(f)} → "
                 f"{fe.where(scenario=s, perturbation=c).mean_max(f'{f}(gyro_bias_estimation=True)')}" for f, s in cols]
        body.append([c, *cells])
    return _table(["condition", *(f"{f} ({s})" for f, s in cols)], body)


MAG_ROWS = (
    ("**RIANN, defaults** (`tau_mag` 9 s, latency estimated online, four network copies)", "mag9d", "riann"),
    ("RIANN, `estimate_mag_delay=false` (latency not compensated)", "mag9d", "riann(estimate_mag_delay=False)"),
    ("RIANN with one network (`ensemble=1`)", "single9d", "riann(ensemble=1)"),
    ("VQF 9D (vqf package defaults)", "mag9d", "vqf"),
    ("Madgwick MARG (β 0.041)", "mag9d", "madgwick"),
    ("Mahony MARG (k_P 1, k_I 0.3)", "mag9d", "mahony"),
)


def mag_summary() -> str:
    body = []
    for label, name, est in MAG_ROWS:
        rows = load(name).where(sensors="9D")
        h, t, i = (rows.values(est, f) for f in ("heading_rmse_deg", "total_rmse_deg", "rmse_deg"))
        body.append([label, f"{sum(h) / len(h):.2f}", f"{max(h):.2f}", f"{sum(t) / len(t):.2f}", f"{max(t):.2f}",
                     f"{sum(i) / len(i):.2f}"])
    return _table(["estimator (9D)", "heading mean", "heading worst", "total mean", "total worst",
                   "inclination mean"], body)


def mag_trials() -> str:
    rows = load("mag9d").where(sensors="9D")
    ests = [("RIANN", "riann"), ("RIANN, latency not compensated", "riann(estimate_mag_delay=False)"),
            ("VQF", "vqf"), ("Madgwick", "madgwick"), ("Mahony", "mahony")]
    body = [[seq[:2], *(f"{rows.where(sequence=seq).values(e, 'heading_rmse_deg')[0]:.2f}" for _, e in ests)]
            for seq in rows.ordered("sequence")]
    return _table(["trial", *(n for n, _ in ests)], body)


README_ROWS = (
    ("paper's restrictive scenario (bias removed at rest)", "scenarios", {"scenario": "restrictive"}),
    ("paper's realistic scenario (from motion onset, random bias)", "scenarios", {"scenario": "realistic"}),
    ("as recorded, stamps jittered 10/20/30 ms", "perturbed",
     {"scenario": "as-recorded", "perturbation": "jitter:10/20/30ms"}),
    ("as recorded, stamped on arrival (0–10 ms late)", "perturbed",
     {"scenario": "as-recorded", "perturbation": "latency:0-10ms"}),
    ("as recorded, FIFO read every 20 ms, stamped on arrival", "perturbed",
     {"scenario": "as-recorded", "perturbation": "fifo:20ms"}),
    ("as recorded, gyro bias (3, 3, 0) °/s", "perturbed", {"scenario": "as-recorded", "perturbation": "bias:3,3,0"}),
    ("as recorded, point samples at random times 10/20/30 ms apart", "perturbed",
     {"scenario": "as-recorded", "perturbation": "jitter:10/20/30ms:points"}),
    ("as recorded, dropouts of 0.1–0.6 s every ~10 s", "perturbed",
     {"scenario": "as-recorded", "perturbation": "dropout:0.1-0.6s@10s"}),
    ("as recorded, a few messages lost about once a second", "perturbed",
     {"scenario": "as-recorded", "perturbation": "dropout:0.01-0.05s@1s"}),
    ("as recorded, the same on a stream stamped on arrival (0–10 ms late)", "perturbed",
     {"scenario": "as-recorded", "perturbation": "latency:0-10ms+dropout:0.01-0.05s@1s"}),
    ("as recorded, resampled to 25 Hz", "rates", {"scenario": "as-recorded", "rate": 25.0}),
)


def readme_table() -> str:
    body = [[label, *(load(name).where(**match).mean_max(e) for e in ESTIMATORS)]
            for label, name, match in README_ROWS]
    return _table(["condition", *(NAMES[e] for e in ESTIMATORS)], body)


UNCERTAINTY_CONDITIONS = {  # perturbation → label; the classical filters' inclination σ is a constant: shown once
    "none": "as recorded", "dropout:0.1-0.6s@10s": "dropout 0.1–0.6 s every 10 s",
    "bias:3,3,0": "gyro bias 3, 3, 0 °/s", "magnetic:offset:20,0,-10": "magnetic offset 20, 0, −10 µT",
    "magnetic:disturb:40@10-20s": "magnetic disturbance 40 µT, 10–20 s"}
MAGNETIC = ("magnetic:offset:20,0,-10", "magnetic:disturb:40@10-20s")


def _uncertainty_groups() -> list[tuple[str, str, dict[str, float | None]]]:
    """(condition label, estimator label, the evaluator's pooled scores) per condition × estimator of
    docs/results/uncertainty.json, RIANN first."""
    from types import SimpleNamespace

    from riann_ros.evaluation.scoring import Score
    from riann_ros.evaluation.uncertainty_report import group_scores

    rows = load("uncertainty")
    out = []
    for cond, label in UNCERTAINTY_CONDITIONS.items():
        for est in ESTIMATORS:
            grp = [SimpleNamespace(score=Score(n_samples=r["n_scored"], n_scored=r["n_scored"], n_unestimated=0,
                                               rmse_deg=r["rmse_deg"], max_err_deg=float("nan"),
                                               **{k: r.get(k) for k in UNCERTAINTY_FIELDS if k != "n_scored"}))
                   for r in rows.where(perturbation=cond, estimator=est).rows]
            if grp:
                out.append((label, f"**{NAMES[est]}**" if est == "riann" else NAMES[est], group_scores(grp)))
    return out


# -- the consensus of RIANN and VQF (docs/consensus.md): its rows from docs/results/consensus*.json, RIANN's and VQF's
# from the runs above (the consensus changes neither) --------------------------------------------------------------
CONSENSUS = ("riann", "vqf", "consensus")


def _with_consensus(base: str, name: str, **match: object) -> Rows:
    """RIANN's and VQF's rows of ``base`` with the consensus's of ``name``, both cut by ``match``."""
    return Rows(tuple(r for r in (*load(base).where(**match).rows, *load(name).where(**match).rows)
                      if r["estimator"] in CONSENSUS))


def _met(rows: Rows) -> tuple[str, str]:
    """The issue's acceptance for one condition: the consensus's mean at most the better of RIANN's and VQF's, its
    worst at most 1.05 × RIANN's worst (on the rounded figures the tables show)."""
    m = {e: round(rows.mean(e), 2) for e in CONSENSUS}
    w = {e: round(max(rows.values(e)), 2) for e in CONSENSUS}
    return ("yes" if m["consensus"] <= min(m["riann"], m["vqf"]) else "**no**",
            "yes" if w["consensus"] <= round(1.05 * w["riann"], 2) else "**no**")


def _consensus_table(rows: Rows, key: str, label: Callable[[object], str]) -> str:
    body = [[label(c), *(rows.where(**{key: c}).mean_max(e) for e in CONSENSUS), *_met(rows.where(**{key: c}))]
            for c in rows.ordered(key)]
    return _table([key.replace("perturbation", "condition"), "RIANN", "VQF", "consensus", "mean ≤ better",
                   "worst ≤ 1.05 RIANN"], body)


def consensus_conditions(scenario: str) -> Callable[[], str]:
    return lambda: _consensus_table(_with_consensus("perturbed", "consensus", scenario=scenario), "perturbation", str)


def consensus_uncertainty() -> str:
    """The consensus's inclination σ per condition (docs/results/consensus.json, 6D: the inclination is the same in
    9D), pooled over the 12 trials."""
    from types import SimpleNamespace

    from riann_ros.evaluation.scoring import Score
    from riann_ros.evaluation.uncertainty_report import group_scores

    body = []
    for scenario in ("as-recorded", "realistic"):
        rows = load("consensus").where(scenario=scenario, estimator="consensus")
        for cond in rows.ordered("perturbation"):
            grp = [SimpleNamespace(score=Score(n_samples=r["n_scored"], n_scored=r["n_scored"], n_unestimated=0,
                                               rmse_deg=r["rmse_deg"], max_err_deg=float("nan"),
                                               **{k: r.get(k) for k in UNCERTAINTY_FIELDS if k != "n_scored"}))
                   for r in rows.where(perturbation=cond).rows]
            g = group_scores(grp)
            body.append([scenario, cond, _pct(g["cover95_pct"]), f"{g['cover95_min']:.1f}–{g['cover95_max']:.1f}",
                         f"{g['nees']:.2f}"])
    return _table(["scenario", "condition", "coverage 95 %", "per trial", "NEES/DOF"], body, left=2)


def consensus_figures() -> str:
    """README: as recorded, and how many conditions meet the acceptance."""
    rows = _with_consensus("perturbed", "consensus", scenario="as-recorded", perturbation="none")
    run = load("consensus")  # the scenarios and conditions the consensus ran
    met = [_met(_with_consensus("perturbed", "consensus", scenario=s, perturbation=c))
           for s in run.ordered("scenario") for c in run.where(scenario=s).ordered("perturbation")]
    return (f"as recorded {rows.mean_max('consensus')}° (RIANN {rows.mean_max('riann')}°, VQF "
            f"{rows.mean_max('vqf')}°); the mean at most the better of the two in {sum(m[0] == 'yes' for m in met)} "
            f"of {len(met)} conditions, the worst trial within 1.05× RIANN's in {sum(m[1] == 'yes' for m in met)}")


def consensus_synthetic() -> str:
    """The synthetic sensor grades of bench/fit_consensus.py (docs/results/consensus_synthetic.json)."""
    from fit_consensus import table

    return table(json.loads((RESULTS / "consensus_synthetic.json").read_text())["rows"])


def _pct(v: float | None) -> str:
    return "–" if v is None else f"{v:.1f}"


def uncertainty_inclination() -> str:
    body = [[cond, est, _pct(g["cover95_pct"]), f"{g['cover95_min']:.1f}–{g['cover95_max']:.1f}", f"{g['nees']:.2f}",
             f"{g['sharpness']:.2f}"]
            for cond, est, g in _uncertainty_groups()
            if est.startswith("**") or cond not in (UNCERTAINTY_CONDITIONS[m] for m in MAGNETIC)]
    return _table(["condition", "estimator", "coverage 95 %", "per trial", "NEES/DOF", "top / bottom decile error"],
                  body, left=2)


def uncertainty_heading() -> str:
    body = [[cond, est, _pct(g["yaw_mag"]), _pct(g["yaw_held"]), "–" if g["yaw_nees"] is None else
             f"{g['yaw_nees']:.2f}"] for cond, est, g in _uncertainty_groups()
            if g["yaw_mag"] is not None or g["yaw_held"] is not None]
    return _table(["condition", "estimator", "field used", "held", "NEES"], body, left=2)


MAGCAL_CONDITIONS = {  # perturbation → label (docs/magnetometer.md, "Online calibration"; BENCHMARKS.md)
    "none": "recorded field",
    "magnetic:offset:20,0,-10": "offset 20, 0, −10 µT",
    "magnetic:offset:0,28,-21": "offset 0, 28, −21 µT (35 µT)",
    "magnetic:soft:1.15,0.05,0,0,0.85,0.05,0.05,0,1+magnetic:offset:10,-20,-20": "soft iron + offset 10, −20, −20 µT",
}


def magcal_table() -> str:
    """Heading RMSE mean / worst over the whole trial and from 60 s on (docs/results/magcal.json, magcal60.json),
    and from 60 s on as a ratio to the estimator's own recorded-field figure from 60 s on; inclination mean."""
    whole, late = load("magcal").where(sensors="9D"), load("magcal60").where(sensors="9D")
    body = []
    for cond, label in MAGCAL_CONDITIONS.items():
        for est in ESTIMATORS:
            w, l0, l1 = (r.where(perturbation=c) for r, c in ((whole, cond), (late, "none"), (late, cond)))
            if not w.values(est, "heading_rmse_deg"):
                continue
            rot = [s[:2] for s in l1.ordered("sequence") if s[:2] not in MAGCAL_LIMITED]
            body.append([label, NAMES[est], w.mean_max(est, "heading_rmse_deg"), l1.mean_max(est, "heading_rmse_deg"),
                         _mean_worst_ratio(l1, l0, est), _mean_worst_ratio(l1.trials(rot), l0.trials(rot), est),
                         f"{w.mean(est):.3f}"])
    return _table(["condition", "estimator", "heading, whole trial", "heading, from 60 s",
                   "from 60 s ÷ recorded field from 60 s (mean / worst trial)",
                   "the same without 10, 15, 27", "inclination mean"], body, left=2)


def _mean_worst_ratio(rows: Rows, base: Rows, est: str) -> str:
    """Heading RMSE of ``rows`` against ``base`` (the same trials): ratio of the means / the worst trial's ratio."""
    h, b = rows.values(est, "heading_rmse_deg"), base.values(est, "heading_rmse_deg")
    mean_r = (sum(h) / len(h)) / (sum(b) / len(b))
    return f"{mean_r:.2f} / {max(x / y for x, y in zip(h, b, strict=True)):.2f}"


def magcal_uncertainty() -> str:
    """RIANN's heading σ over the whole trial, pooled over the trials (docs/results/magcal.json)."""
    from types import SimpleNamespace

    from riann_ros.evaluation.scoring import Score
    from riann_ros.evaluation.uncertainty_report import group_scores

    rows = load("magcal").where(sensors="9D", estimator="riann")
    body = []
    for cond, label in MAGCAL_CONDITIONS.items():
        grp = [SimpleNamespace(score=Score(n_samples=r["n_scored"], n_scored=r["n_scored"], n_unestimated=0,
                                           rmse_deg=r["rmse_deg"], max_err_deg=float("nan"),
                                           **{k: r.get(k) for k in UNCERTAINTY_FIELDS if k != "n_scored"}))
               for r in rows.where(perturbation=cond).rows]
        g = group_scores(grp)
        conv = [r["mag_converged_after_s"] for r in rows.where(perturbation=cond).rows]
        done = [c for c in conv if c is not None]
        body.append([label, _pct(g["yaw_mag"]), _pct(g["yaw_held"]),
                     "–" if g["yaw_nees"] is None else f"{g['yaw_nees']:.2f}",
                     f"{len(done)}/{len(conv)}" + (f", {min(done):.0f}–{max(done):.0f} s" if done else "")])
    return _table(["condition", "coverage 95 %, field used", "held", "NEES", "calibrated (trials, after)"], body)


def magcal_saved() -> str:
    """The saved calibration's second run (docs/results/magcal_saved.json, bench/bench_magcal_saved.py)."""
    data = json.loads((RESULTS / "magcal_saved.json").read_text())
    body = [[r["trial"], f"{r['first']:.2f}", f"{r['second']:.2f}", f"{r['recorded']:.2f}",
             f"{r['second'] - r['recorded']:+.2f}"] for r in data["rows"]]
    d = [abs(r["second"] - r["recorded"]) for r in data["rows"]]
    body.append(["mean / worst of the absolute difference", "", "", "", f"{sum(d) / len(d):.2f} / {max(d):.2f}"])
    return _table(["trial", "first run (offset, calibrating)", "second run (its saved calibration)",
                   "recorded field", "second − recorded"], body)


# ---- figures within sentences ----------------------------------------------------------------------
def _fig(rows: Rows, est: str) -> str:
    return rows.mean_max(est)


#: the demo's conditions (the Makefile's ``-p``), as the README says them; another condition is shown as written
DEMO_CONDITIONS = {"none": "as recorded", "jitter:10/20/30ms": "stamps jittered 10/20/30 ms",
                   "bias:3,3,0": "gyro bias (3, 3, 0) °/s"}


#: the fast trials measured for the demo's real recording (bags/README.md), and the conditions shown for them
DEMO_CANDIDATES = ("06", "07", "15", "21")
CANDIDATE_CONDITIONS = ("none", "jitter:10/20/30ms", "bias:3,3,0", "dropout:0.1-0.6s@10s")


def demo_candidates() -> str:
    """Per candidate trial (as recorded, perturbed.json) and condition: each estimator's RMSE."""
    rows = load("perturbed").where(scenario="as-recorded").trials(DEMO_CANDIDATES)
    body = [[f"`{seq}`", f"`{c}`", *(f"{v:.2f}" for e in ESTIMATORS
                                      for v in rows.where(sequence=seq, perturbation=c).values(e))]
            for seq in rows.ordered("sequence") for c in CANDIDATE_CONDITIONS]
    return _table(["trial", "condition", *(NAMES[e] for e in ESTIMATORS)], body, left=2)


def run_rows(results_json: Path) -> Rows:
    """The rows of a ``riann-bag-eval`` results.json as the tables read them (e.g. a fresh ``make demo``)."""
    return Rows(tuple(json.loads(results_json.read_text())["results"]))


def _synthetic(rows: Rows, synthetic: bool) -> Rows:
    """The rows of the project's generated bags (sequences ``synthetic_…``), or of the real recordings."""
    return Rows(tuple(r for r in rows.rows if r["sequence"].startswith("synthetic_") == synthetic))


def _demo_table(rows: Rows, first: str, cell: Callable[[Rows, str], str]) -> str:
    body = [[DEMO_CONDITIONS.get(c, f"`{c}`"), *(cell(rows.where(perturbation=c), e) for e in DEMO_ESTIMATORS)]
            for c in rows.ordered("perturbation")]
    return _table([first, *(NAMES[e] for e in DEMO_ESTIMATORS)], body)


def demo_real(rows: Rows | None = None) -> str:
    """The demo's real recording (one sequence): its RMSE per condition and estimator."""
    real = _synthetic(load("demo") if rows is None else rows, synthetic=False)
    (seq,) = real.ordered("sequence")
    return _demo_table(real, f"`{seq}`", lambda r, e: f"{r.values(e)[0]:.2f}")


def demo_synthetic(rows: Rows | None = None) -> str:
    """The demo's synthetic bags: mean / worst RMSE over them per condition and estimator."""
    syn = _synthetic(load("demo") if rows is None else rows, synthetic=True)
    return _demo_table(syn, f"{len(syn.ordered('sequence'))} synthetic bags", Rows.mean_max)


def _as_recorded(condition: str) -> Rows:
    return load("perturbed").where(scenario="as-recorded", perturbation=condition)


def streams_figures() -> str:
    parts = [("native", "none"), ("stamps jittered 10/20/30 ms", "jitter:10/20/30ms"),
             ("point samples at random times", "jitter:10/20/30ms:points"),
             ("stamped on arrival 0–10 ms late", "latency:0-10ms"), ("a FIFO read every 20 ms", "fifo:20ms"),
             ("a (3, 3, 0) °/s bias", "bias:3,3,0"), ("dropouts of 0.1–0.6 s", "dropout:0.1-0.6s@10s")]
    return ", ".join(f"{text} {_fig(_as_recorded(c), 'riann')}° (VQF {_fig(_as_recorded(c), 'vqf')}°)"
                     for text, c in parts)


def rate_ratio_figure() -> str:
    native = {r["sequence"]: r["rmse_deg"] for r in _as_recorded("none").where(estimator="riann").rows}
    worst = max(r["rmse_deg"] / native[r["sequence"]] for r in load("rates").where(estimator="riann").rows)
    return f"{worst:.2f}×"


def ensemble_figures() -> str:
    one = load("single6d").where(scenario="as-recorded")
    return (f"{_fig(one, 'riann(ensemble=1)')}° → {_fig(_as_recorded('none'), 'riann')}° "
            f"(VQF {_fig(_as_recorded('none'), 'vqf')}°)")


def single_network_figures() -> str:
    one = load("single6d")
    return (f"as recorded {_fig(one.where(scenario='as-recorded'), 'riann(ensemble=1)')}, realistic "
            f"{_fig(one.where(scenario='realistic'), 'riann(ensemble=1)')}")


def mag_figures() -> str:
    rows = load("mag9d").where(sensors="9D")
    hd = "heading_rmse_deg"
    return (f"RIANN {rows.mean_max('riann', hd)} (its magnetometer latency estimated online and compensated; "
            f"{rows.mean_max('riann(estimate_mag_delay=False)', hd)} without), VQF {rows.mean_max('vqf', hd)}, "
            f"Madgwick {rows.mean_max('madgwick', hd)}, Mahony {rows.mean_max('mahony', hd)}")


def realistic_lead() -> str:
    rows = load("scenarios").where(scenario="realistic")
    return f"{rows.mean('riann'):.2f} vs {rows.mean('vqf'):.2f}"


def as_recorded_pair() -> str:
    return f"{_fig(_as_recorded('none'), 'riann')} vs {_fig(_as_recorded('none'), 'vqf')}"


def tuned_figures() -> str:
    rows = load("tuned")
    tuned = {e.split("(")[0]: e for e in rows.estimators() if e.endswith("tuned")}
    return (f"RIANN {rows.mean('riann'):.2f}° untuned; VQF {rows.mean(tuned['vqf']):.2f}°, Madgwick "
            f"{rows.mean(tuned['madgwick']):.2f}°, Mahony {rows.mean(tuned['mahony']):.2f}° tuned")


def realistic_rates_figures() -> str:
    rows = load("rates_realistic")
    means = [rows.where(rate=f).mean("riann") for f in rows.ordered("rate")]
    native = load("scenarios").where(scenario="realistic").mean("riann")
    return f"{min(means):.2f}–{max(means):.2f}° (native 285.7 Hz: {native:.2f}°)"


# ---------------------------------------------------------------------------------------------------
# executors (bench/bench_cluster.py --save: docs/results/cluster.json)
# ---------------------------------------------------------------------------------------------------
CLUSTER_MODES = ("in-process", "--jobs 2", "--scheduler local:2")
FLEET_BAGS, FLEET_HOURS, FLEET_CORES = 10_000, 1.0, 64  # the extrapolated corpus: bags, hours each, worker cores


def _cluster() -> dict:
    return json.loads((RESULTS / "cluster.json").read_text())


def _ratios() -> list[float]:
    walls = _cluster()["held_out"]["walls_s"]
    return [c / j for c, j in zip(walls["--scheduler local:2"], walls["--jobs 2"], strict=True)]


def cluster_held_out() -> str:
    c = _cluster()
    h = c["held_out"]
    body = []
    for m in CLUSTER_MODES:
        walls, loads = h["walls_s"][m], h["loads"][m]
        cpus = ", ".join(f"{x:.0f}" for x in h["cpu_s"][m]) if m == "in-process" else "–"  # workers not accounted
        body.append([f"`{m}`" if m != "in-process" else m, ", ".join(f"{w:.1f}" for w in walls),
                     f"**{statistics.median(walls):.1f}**", cpus,
                     ", ".join(f"{a:.1f} / {b:.1f}" for a, b in loads)])
    r = _ratios()
    note = (f"`{c['command']}` ({c['machine']}): {h['trials']} trials, {h['recorded_s'] / 60:.0f} min of recording, "
            f"`{c['held_out_args']}`, {h['rows']} rows; the modes in turn, round by round; every mode's RMSEs "
            + (f"within {h['max_rmse_diff_deg']:.0e}° of" if h["max_rmse_diff_deg"] else "equal to")
            + f" the in-process ones. **`--scheduler local:2` / "
            f"`--jobs 2`, round by round: {', '.join(f'{x:.2f}' for x in r)}** (median {statistics.median(r):.2f}).")
    return _table(["mode", "wall s, per round", "median s", "CPU s", "1-min load before / after"],
                  body) + "\n\n" + note


def cluster_many() -> str:
    c = _cluster()
    body = [[f"`{r['mode']}`", str(r["inputs"]), f"{r['wall_s']:.1f}", f"{1000 * r['wall_s'] / r['inputs']:.0f}",
             f"{r['client_peak_rss_mb']:.0f}", f"{r['shards_bytes_per_input'] / 1024:.1f}",
             f"{r['results_json_bytes_per_input'] / 1024:.1f}", f"{r['load'][0]:.1f} / {r['load'][1]:.1f}"]
            for r in c["many"]]
    return _table(["mode", "inputs", "wall s", "ms per input", "client peak RSS MB", "shards kB per input",
                   "results.json kB per input", "1-min load before / after"], body)


def cluster_ratio() -> str:
    r = _ratios()
    return f"{statistics.median(r):.2f} ({', '.join(f'{x:.2f}' for x in r)} round by round)"


def cluster_fleet() -> str:
    """What a fleet of FLEET_BAGS bags of FLEET_HOURS each costs, from the measured CPU per recorded second."""
    c = _cluster()
    h = c["held_out"]
    per_rec = statistics.median(h["cpu_s"]["in-process"]) / h["recorded_s"]
    core_h = FLEET_BAGS * FLEET_HOURS * 3600 * per_rec / 3600
    short = next(r for r in c["many"] if r["mode"] == "--scheduler local:2")
    overhead = 2 * short["wall_s"] / short["inputs"]  # worker-seconds per short input on 2 workers, work included
    return (f"{per_rec:.3f} CPU s per recorded second (median in-process CPU of the held-out-sized run, "
            f"{h['recorded_s'] / 60:.0f} min of BROAD, 4 estimators × 3 scenarios), so {FLEET_BAGS:,} bags of "
            f"{FLEET_HOURS:.0f} h each are about **{core_h:,.0f} core-hours**: **{core_h / FLEET_CORES:.0f} h on "
            f"{FLEET_CORES} worker cores**, if the work spreads evenly over workers (measured here on 2 only); "
            f"each input costs at most {overhead:.2f} worker-seconds more whatever its length ({short['inputs']} "
            f"short inputs on local:2, their work included: {FLEET_BAGS * overhead / 60:.0f} worker-minutes for "
            f"{FLEET_BAGS:,}); the shards take {FLEET_BAGS * short['shards_bytes_per_input'] / 1e6:.0f} MB, "
            f"results.json {FLEET_BAGS * short['results_json_bytes_per_input'] / 1e6:.0f} MB, and the client "
            f"peaked at {short['client_peak_rss_mb']:.0f} MB for {short['inputs']} inputs")


TABLES: dict[str, Callable[[], str]] = {
    **EVO_TABLES,
    "readme-broad": readme_table,
    "readme-demo-real": demo_real,
    "readme-demo-synthetic": demo_synthetic,
    "demo-candidates": demo_candidates,
    "readme-streams": streams_figures,
    "readme-rate-ratio": rate_ratio_figure,
    "readme-ensemble": ensemble_figures,
    "single-network": single_network_figures,
    "readme-9d": mag_figures,
    "as-recorded-pair": as_recorded_pair,
    "scenarios": scenarios_table,
    "sample-delay": sample_delay_table,
    "sample-delay-timing": sample_delay_timing,
    "realistic-lead": realistic_lead,
    "perturbed-as-recorded": perturbed("as-recorded"),
    "perturbed-realistic": perturbed("realistic"),
    "dropout-six": dropout_six,
    "rate-ratios": rate_ratios,
    "rates-as-recorded": rates_table("rates", ESTIMATORS),
    "rates-realistic": rates_table("rates_realistic", ("riann", "vqf", "madgwick")),
    "realistic-rates-figures": realistic_rates_figures,
    "tuned": tuned_table,
    "tuned-figures": tuned_figures,
    "frontend": frontend_table,
    "mag-summary": mag_summary,
    "mag-trials": mag_trials,
    "uncertainty-inclination": uncertainty_inclination,
    "consensus-as-recorded": consensus_conditions("as-recorded"),
    "consensus-uncertainty": consensus_uncertainty,
    "readme-consensus": consensus_figures,
    "consensus-synthetic": consensus_synthetic,
    "uncertainty-heading": uncertainty_heading,
    "magcal": magcal_table,
    "magcal-uncertainty": magcal_uncertainty,
    "magcal-saved": magcal_saved,
    "trust-lag": lambda: lag_table(load),
    "trust-nocal": lambda: nocal_table(load),
    "trust-recorded": lambda: recorded_table(load),
    "cluster-held-out": cluster_held_out,
    "cluster-many": cluster_many,
    "cluster-ratio": cluster_ratio,
    "cluster-fleet": cluster_fleet,
}


# ---------------------------------------------------------------------------------------------------
# pages
# ---------------------------------------------------------------------------------------------------
def render(text: str, made: dict[str, str] | None = None) -> str:
    """``text`` with every marked block replaced by what its table writes (``made``: cache by name)."""
    made = {} if made is None else made

    def sub(m: re.Match[str]) -> str:
        name = m["name"]
        if name not in TABLES:
            raise KeyError(f"unknown results block {name!r}; known: {', '.join(TABLES)}")
        if name not in made:
            made[name] = TABLES[name]()
        inline = "\n" not in m["body"]
        if inline:
            return f"<!-- results:{name} -->{made[name]}<!-- /results:{name} -->"
        line = text[text.rfind("\n", 0, m.start()) + 1:m.start()]
        indent = line if not line.strip() else ""  # a table inside a list item keeps the item's indent
        body = "".join(f"{indent}{row}\n" for row in made[name].split("\n"))
        return f"<!-- results:{name} -->\n{body}{indent}<!-- /results:{name} -->"

    return MARKER.sub(sub, text)


def stale(root: Path = ROOT) -> list[str]:
    """The pages (relative paths) whose marked blocks differ from what the tables write."""
    made: dict[str, str] = {}
    return [p for p in PAGES if (root / p).read_text() != render((root / p).read_text(), made)]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--check", action="store_true", help="only compare; exit 1 when a page differs")
    sub = ap.add_subparsers(dest="cmd")
    t = sub.add_parser("trim", help="cut results.json files down to the table fields: docs/results/NAME.json")
    t.add_argument("name")
    t.add_argument("sources", type=Path, nargs="+")
    t.add_argument("--command", required=True, help="the command that made them (as the docs show it)")
    t.add_argument("--uncertainty", action="store_true", help="keep the uncertainty scores too (σ histograms)")
    args = ap.parse_args(argv)
    if args.cmd == "trim":
        print(f"wrote {trim(args.name, args.sources, args.command, args.uncertainty)}")
        return 0
    bad = stale()
    if args.check:
        for p in bad:
            print(f"{p}: a results block differs from docs/results/ (run bench/results_tables.py)", file=sys.stderr)
        return 1 if bad else 0
    made: dict[str, str] = {}
    for p in bad:
        (ROOT / p).write_text(render((ROOT / p).read_text(), made))
        print(f"rewrote {p}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
