"""Saved runs side by side, evo_res style (``riann-bag-eval --compare A B``; ROS-free).

A and B are results.json files of riann-bag-eval (or their ``--out`` folders; the same run twice to compare rows of
one run), each narrowed by selections (``--select-a estimator=madgwick``, ``--select-b perturbation=jitter:10ms``,
``--select scenario=as-recorded`` for both; :func:`parse_selection`).

Matching: rows always pair by sequence. Of the other axes — estimator (its label holds its parameters), scenario,
perturbation, rate, sensors (6D, or 9D: the magnetometer used) — those on which A and B share a value also have to
agree (so two runs of the same settings pair row by row, and a 9D row never pairs with a 6D one while both sides
have rows of the same sensors); an axis whose values A and B do not share at all (``madgwick`` in A,
``madgwick(beta=0.1)`` in B; a clean run and a perturbed one; a 9D run and a 6D one) is not matched, each side's
value is shown and the text says so. Run settings that change every score (seed, initial rest, ``--score-from``,
``--offset-steps``, the scenarios' bias) are compared too: where A's and B's differ, the text says which
(:func:`riann_ros.evaluation.compare_text.setting_differences`). A statistic (``--metric``: ``rmse`` by default, or
another of evo ape's mean, median, std, min, max; heading and total errors where scored) is compared as B − A: per
group n and mean / median / max over the sequences of A, of B and of B − A; per sequence A, B and B − A, and every
statistic of e_α; rows of one side that found no partner are counted. No estimator runs.
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from riann_ros.evaluation import plots as pl
from riann_ros.evaluation.aggregate import rate_label, rate_order, scenario_order
from riann_ros.evaluation.errors import EvalError
from riann_ros.evaluation.outdir import prepare_out
from riann_ros.evaluation.perturb import NONE
from riann_ros.evaluation.results import NATIVE, ResultRow
from riann_ros.evaluation.scoring import ERRORS, STATS, stat_field

AXES = ("estimator", "scenario", "perturbation", "rate", "sensors")  # matched when A and B share a value
SELECT_FIELDS = ("sequence", "dataset", *AXES)
PRINT_PAIRS = 40  # the per-sequence statistics are printed for at most this many pairs (all in compare.csv)



def metrics() -> list[str]:
    """``--metric`` names: ``rmse`` … ``max`` (e_α), ``heading_rmse`` …, ``total_rmse`` …"""
    return [st if err == "inclination" else f"{err}_{st}" for err in ERRORS for st in STATS]


def parse_metric(text: str) -> tuple[str, str]:
    """``"median"`` → ("inclination", "median"); ``"heading_rmse"`` → ("heading", "rmse")."""
    t = text.strip().lower().replace("-", "_")
    for err in ERRORS:
        for st in STATS:
            if t == (st if err == "inclination" else f"{err}_{st}"):
                return err, st
    raise ValueError(f"unknown --metric {text!r}; known: {', '.join(metrics())}")


@dataclass(frozen=True)
class Selection:
    """``field=value`` pairs a side's rows must match (``rate``: ``native`` or Hz; ``estimator``: a label of the
    tables, e.g. ``madgwick(beta=0.1)``, or a spec as given to ``-e``, e.g. ``madgwick:beta=0.1``)."""

    items: tuple[tuple[str, str], ...] = ()

    def text(self) -> str:
        return ", ".join(f"{k}={v}" for k, v in self.items)


def parse_selection(texts: Iterable[str]) -> Selection:
    """``["estimator=madgwick", "perturbation=none"]`` → :class:`Selection` (ValueError naming the fields)."""
    items = []
    for t in texts:
        key, sep, value = t.partition("=")
        key = key.strip().lower()
        if not sep or key not in SELECT_FIELDS or not value.strip():
            raise ValueError(f"bad selection {t!r}: expected FIELD=VALUE with FIELD one of {', '.join(SELECT_FIELDS)}")
        items.append((key, value.strip()))
    return Selection(tuple(items))


def _spec_label(value: str) -> str | None:
    """The table label of an estimator spec as given to ``-e`` (``madgwick:beta=0.1`` → ``madgwick(beta=0.1)``)."""
    from riann_ros.evaluation.specs import parse_estimator

    try:
        return parse_estimator(value).label
    except (ValueError, ImportError):
        return None


def _value(r: ResultRow, key: str) -> str:
    v = getattr(r, key)
    return rate_label(v) if key == "rate" else str(v)


def select(rows: Sequence[ResultRow], sel: Selection, side: str) -> list[ResultRow]:
    """The rows matching every item of ``sel``; EvalError naming what the side has when an item matches none."""
    out = list(rows)
    for key, value in sel.items:
        have = list(dict.fromkeys(_value(r, key) for r in out))
        want = value
        if key == "estimator" and value not in have:
            want = _spec_label(value) or value
        elif key == "rate" and value.lower() != NATIVE:
            try:
                want = rate_label(float(value.lower().removesuffix("hz").strip()))
            except ValueError:
                want = value
        kept = [r for r in out if _value(r, key) == want]
        if not kept:
            raise EvalError(f"{side}: no row with {key}={value} (its {key} values: {', '.join(have) or 'none'})")
        out = kept
    return out


@dataclass
class Saved:
    """One saved run: its rows and what produced them."""

    path: Path
    label: str
    command: str
    rows: list[ResultRow]
    settings: dict = field(default_factory=dict)  # results.json's settings


def run_label(path: Path) -> str:
    """``eval_a`` for ``eval_a/results.json``, else the file name."""
    return path.parent.name if path.name == "results.json" and path.parent.name else path.name


def load(path: str | Path) -> Saved:
    """The scored rows of a results.json written by riann-bag-eval (EvalError naming the file otherwise); rows of
    inputs without a reference carry no scores and are left out."""
    p = Path(path)
    if p.is_dir():
        p = p / "results.json"
    try:
        data = json.loads(p.read_text())
    except FileNotFoundError:
        raise EvalError(f"{p}: no such file (give a results.json of riann-bag-eval, or its --out folder)") from None
    except (OSError, ValueError) as exc:
        raise EvalError(f"{p}: cannot read as JSON: {exc}") from exc
    if not isinstance(data, dict) or not isinstance(data.get("results"), list):
        raise EvalError(f"{p}: not a results.json of riann-bag-eval (no 'results' list)")
    try:
        rows = [row for row in (ResultRow.from_dict(d) for d in data["results"]) if row.has_reference]
    except (KeyError, TypeError, ValueError) as exc:
        raise EvalError(f"{p}: a result row lacks or garbles {exc}") from exc
    settings = data.get("settings")
    settings = settings if isinstance(settings, dict) else {}
    return Saved(p, run_label(p), str(settings.get("command", "")), rows, settings)


Side = tuple[str, str, str, str | float, str]  # estimator, scenario, perturbation, rate, sensors of one side's row


def side_of(r: ResultRow) -> Side:
    return (r.estimator, r.scenario, r.perturbation, r.rate, r.sensors)


@dataclass
class Pair:
    """A row of A and a row of B on the same sequence."""

    sequence: str
    a: ResultRow
    b: ResultRow
    metric: tuple[str, str] = ("inclination", "rmse")

    @property
    def va(self) -> float:
        return pair_stat(self.a, self.metric)

    @property
    def vb(self) -> float:
        return pair_stat(self.b, self.metric)

    @property
    def diff(self) -> float:
        return self.vb - self.va


def pair_stat(r: ResultRow, metric: tuple[str, str]) -> float:
    v = r.score.stat(*metric)
    return float("nan") if v is None else v


@dataclass
class GroupDiff:
    """The statistics of A and B over the sequences of one group: the same A side and B side (estimator, scenario,
    perturbation, rate)."""

    a_side: Side
    b_side: Side
    n: int
    a: dict[str, float]  # mean, median, max
    b: dict[str, float]

    def diff(self, stat: str) -> float:
        return self.b[stat] - self.a[stat]

    # the side's fields, for the axes both sides share (the same value on either side)
    @property
    def estimator(self) -> str:
        return self.a_side[0]

    @property
    def scenario(self) -> str:
        return self.a_side[1]

    @property
    def perturbation(self) -> str:
        return self.a_side[2]

    @property
    def rate(self) -> str | float:
        return self.a_side[3]

    @property
    def sensors(self) -> str:
        return self.a_side[4]


@dataclass
class Comparison:
    a: Saved
    b: Saved
    matched: tuple[str, ...] = AXES  # the axes A and B had to agree on (besides the sequence)
    metric: tuple[str, str] = ("inclination", "rmse")
    pairs: list[Pair] = field(default_factory=list)
    only_a: list[ResultRow] = field(default_factory=list)
    only_b: list[ResultRow] = field(default_factory=list)
    selections: tuple[Selection, Selection] = (Selection(), Selection())
    without_metric: int = 0  # pairs left out: a side without the statistic (an older file, a 6D heading)

    @property
    def differing(self) -> tuple[str, ...]:
        """The axes not matched: each side's value is shown."""
        return tuple(a for a in AXES if a not in self.matched)

    def groups(self) -> list[GroupDiff]:
        by: dict[tuple[Side, Side], list[Pair]] = {}
        for p in self.pairs:
            by.setdefault((side_of(p.a), side_of(p.b)), []).append(p)
        ests = list(dict.fromkeys(k[i][0] for k in by for i in (0, 1)))
        scns = scenario_order(k[i][1] for k in by for i in (0, 1))
        prts = list(dict.fromkeys(k[i][2] for k in by for i in (0, 1)))

        def order(k: tuple[Side, Side]) -> tuple:
            (ea, sa, pa, ra, na), (eb, sb, pb, rb, nb) = k
            return (scns.index(sa), scns.index(sb), prts.index(pa), prts.index(pb), rate_order(ra), rate_order(rb),
                    na, nb, ests.index(ea), ests.index(eb))

        out = []
        for k in sorted(by, key=order):
            ps = by[k]
            out.append(GroupDiff(k[0], k[1], len(ps), _stats(np.array([p.va for p in ps])),
                                 _stats(np.array([p.vb for p in ps]))))
        return out


def _stats(v: np.ndarray) -> dict[str, float]:
    return {"mean": float(np.mean(v)), "median": float(np.median(v)), "max": float(np.max(v))}


def _shared_axes(ra: Sequence[ResultRow], rb: Sequence[ResultRow]) -> tuple[str, ...]:
    """The axes on which A and B share at least one value: those have to agree."""
    return tuple(ax for ax in AXES if {getattr(r, ax) for r in ra} & {getattr(r, ax) for r in rb})


def compare(a: Saved, b: Saved, sel_a: Selection = Selection(), sel_b: Selection = Selection(),
            metric: tuple[str, str] = ("inclination", "rmse")) -> Comparison:
    """Pair the (selected) rows of ``a`` and ``b`` by sequence and the axes they share; EvalError when no pair."""
    ra, rb = select(a.rows, sel_a, f"A ({a.path})"), select(b.rows, sel_b, f"B ({b.path})")
    matched = _shared_axes(ra, rb)
    cmp = Comparison(a, b, matched, metric, selections=(sel_a, sel_b))

    def key(r: ResultRow) -> tuple:
        return (r.sequence, *(getattr(r, ax) for ax in matched))

    by_b: dict[tuple, list[ResultRow]] = {}
    for r in rb:
        by_b.setdefault(key(r), []).append(r)
    keys_a = {key(r) for r in ra}
    pairs = [Pair(r.sequence, r, s, metric) for r in ra for s in by_b.get(key(r), [])]
    cmp.pairs = [p for p in pairs if math.isfinite(p.va) and math.isfinite(p.vb)]
    cmp.without_metric = len(pairs) - len(cmp.pairs)
    cmp.only_a = [r for r in ra if key(r) not in by_b]
    cmp.only_b = [r for r in rb if key(r) not in keys_a]
    if not cmp.pairs:
        if pairs:
            raise EvalError(f"{a.path} and {b.path}: no pair of rows has the {metric_text(metric)} (an older "
                            "results.json, or a heading statistic of 6D rows)")
        seq_a, seq_b = sorted({r.sequence for r in ra}), sorted({r.sequence for r in rb})
        raise EvalError(f"{a.path} and {b.path} have no result in common: rows pair by sequence"
                        + (f" and by {', '.join(matched)}" if matched else "")
                        + f"; sequences in A: {', '.join(seq_a[:6])}; in B: {', '.join(seq_b[:6])}")
    return cmp


def metric_text(metric: tuple[str, str]) -> str:
    err, st = metric
    return {"inclination": "attitude (inclination e_α)", "heading": "heading", "total": "total angle",
            "heading_drift": "heading drift"}[err] + (
        " RMSE" if st == "rmse" else f" {st} error")


def rate_text(rate: str | float) -> str:
    return str(rate) if rate == NATIVE else f"{float(rate):g} Hz"


def side_text(side: Side, axis: str) -> str:
    v = side[AXES.index(axis)]
    return rate_text(v) if axis == "rate" else str(v)


def ordered_pairs(cmp: Comparison) -> list[Pair]:
    order = {(g.a_side, g.b_side): i for i, g in enumerate(cmp.groups())}
    return sorted(cmp.pairs, key=lambda p: order[(side_of(p.a), side_of(p.b))])


def _csv_stats(cmp: Comparison) -> list[tuple[str, str]]:
    """(column stem, metric) of the statistics in compare.csv: every one of e_α; heading and total where scored."""
    errs = [e for e in ERRORS if e == "inclination" or any(p.a.score.stat(e, "rmse") is not None for p in cmp.pairs)]
    return [(stat_field(e, st).removesuffix("_deg").removesuffix("_err"), f"{e}:{st}") for e in errs for st in STATS
            if (e, st) != ("inclination", "rmse")]


def write_csv(path: Path, cmp: Comparison) -> None:
    """compare.csv: one row per pair. ``sequence, scenario, perturbation, rate, estimator`` are A's,
    ``rmse_a_deg, rmse_b_deg, diff_deg`` the e_α RMSEs and B − A, then B's side, the ``--metric`` and its
    difference, A's and B's ``sensors``, and A's and B's value of every other statistic."""
    extra = _csv_stats(cmp)
    metric = cmp.metric[1] if cmp.metric[0] == "inclination" else f"{cmp.metric[0]}_{cmp.metric[1]}"
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["sequence", "scenario", "perturbation", "rate", "estimator", "rmse_a_deg", "rmse_b_deg",
                    "diff_deg", "scenario_b", "perturbation_b", "rate_b", "estimator_b", "metric", "metric_diff_deg",
                    "sensors", "sensors_b",
                    *(f"{stem}_{x}_deg" for stem, _ in extra for x in ("a", "b"))])

        def num(v: float | None) -> str:
            return "" if v is None or not math.isfinite(v) else f"{v:.6f}"

        for p in ordered_pairs(cmp):
            a, b = p.a, p.b
            cells = [p.sequence, a.scenario, a.perturbation, a.rate, a.estimator, num(a.rmse_deg), num(b.rmse_deg),
                     num(b.rmse_deg - a.rmse_deg), b.scenario, b.perturbation, b.rate, b.estimator, metric,
                     num(p.diff), a.sensors, b.sensors]
            for _, m in extra:
                err, st = m.split(":")
                cells += [num(a.score.stat(err, st)), num(b.score.stat(err, st))]
            w.writerow(cells)


def differences(cmp: Comparison) -> dict[tuple[str, str], list[float]]:
    """(panel, tick) -> the per-sequence differences B − A, in table order: a panel per scenario × perturbation ×
    rate (each side's when they differ), a tick per estimator (``A → B`` when they differ)."""
    out: dict[tuple[str, str], list[float]] = {}
    for g in cmp.groups():
        parts = []
        for ax in ("scenario", "perturbation", "rate", "sensors"):
            a, b = side_text(g.a_side, ax), side_text(g.b_side, ax)
            if ax in cmp.differing:
                parts.append(f"{a} → {b}")
            elif not ((ax == "perturbation" and a == NONE) or (ax == "rate" and a == NATIVE)
                      or (ax == "sensors" and a == "6D")):
                parts.append(a)
        tick = g.a_side[0] if g.a_side[0] == g.b_side[0] else f"{g.a_side[0]} → {g.b_side[0]}"
        out[(", ".join(parts), tick)] = [p.diff for p in cmp.pairs if (side_of(p.a), side_of(p.b)) == (g.a_side,
                                                                                                      g.b_side)]
    return out


def write_comparison(out: Path, cmp: Comparison, plots: bool = True, replace: bool = False) -> list[Path]:
    """compare.csv and (``plots``) compare_rmse.png/.svg in ``out`` (the --out policy of
    :func:`~riann_ros.evaluation.outdir.prepare_out`); returns the files written."""
    prepare_out(out, replace)
    written = [out / "compare.csv"]
    try:
        write_csv(written[0], cmp)
        if plots:
            written += pl.plot_differences(differences(cmp), cmp.a.label, cmp.b.label, out,
                                           ylabel=metric_text(cmp.metric))
    except BaseException:
        for f in written:
            f.unlink(missing_ok=True)
        raise
    return written
