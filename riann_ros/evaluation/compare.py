"""Two saved runs side by side, evo_res style (``riann-bag-eval --compare A/results.json B/results.json``; ROS-free).

Rows of the two results.json files are matched by sequence × scenario × perturbation × rate × estimator; the
difference is B − A of the per-sequence RMSE. Per estimator × scenario × perturbation (× rate when several): n,
mean / median / max of A and of B over the matched sequences and their differences; and per sequence. Rows in
one run only are counted and listed, not compared. No estimator runs.
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from riann_ros.evaluation import plots as pl
from riann_ros.evaluation.aggregate import rate_order, scenario_order
from riann_ros.evaluation.errors import EvalError
from riann_ros.evaluation.outdir import prepare_out
from riann_ros.evaluation.perturb import NONE
from riann_ros.evaluation.results import NATIVE, ResultRow
from riann_ros.evaluation.uncertainty_report import format_uncertainty_comparison

Key = tuple[str, str, str, str | float, str]  # sequence, scenario, perturbation, rate, estimator
Group = tuple[str, str, str, str | float]  # estimator, scenario, perturbation, rate


@dataclass
class Saved:
    """One saved run: its rows and what produced them."""

    path: Path
    label: str
    command: str
    rows: list[ResultRow]


def run_label(path: Path) -> str:
    """``eval_a`` for ``eval_a/results.json``, else the file name."""
    return path.parent.name if path.name == "results.json" and path.parent.name else path.name


def load(path: str | Path) -> Saved:
    """The rows of a results.json written by riann-bag-eval (EvalError naming the file otherwise)."""
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
        rows = [ResultRow.from_dict(d) for d in data["results"]]
    except (KeyError, TypeError, ValueError) as exc:
        raise EvalError(f"{p}: a result row lacks or garbles {exc}") from exc
    return Saved(p, run_label(p), str((data.get("settings") or {}).get("command", "")), rows)


def key(r: ResultRow) -> Key:
    return (r.sequence, r.scenario, r.perturbation, r.rate, r.estimator)


@dataclass
class Pair:
    key: Key
    a: float
    b: float

    @property
    def diff(self) -> float:
        return self.b - self.a


@dataclass
class GroupDiff:
    """The statistics of A and B over the sequences both runs have, for one estimator × scenario × perturbation ×
    rate."""

    estimator: str
    scenario: str
    perturbation: str
    rate: str | float
    n: int
    a: dict[str, float]  # mean, median, max
    b: dict[str, float]

    def diff(self, stat: str) -> float:
        return self.b[stat] - self.a[stat]


@dataclass
class Comparison:
    a: Saved
    b: Saved
    pairs: list[Pair] = field(default_factory=list)
    only_a: list[Key] = field(default_factory=list)
    only_b: list[Key] = field(default_factory=list)

    def groups(self) -> list[GroupDiff]:
        by: dict[Group, list[Pair]] = {}
        for p in self.pairs:
            _, scn, prt, rate, est = p.key
            by.setdefault((est, scn, prt, rate), []).append(p)
        ests = list(dict.fromkeys(p.key[4] for p in self.pairs))
        scns = scenario_order(p.key[1] for p in self.pairs)
        prts = list(dict.fromkeys(p.key[2] for p in self.pairs))
        out = []
        for (est, scn, prt, rate), ps in sorted(
                by.items(), key=lambda kv: (scns.index(kv[0][1]), prts.index(kv[0][2]), rate_order(kv[0][3]),
                                            ests.index(kv[0][0]))):
            a, b = np.array([p.a for p in ps]), np.array([p.b for p in ps])
            out.append(GroupDiff(est, scn, prt, rate, len(ps), _stats(a), _stats(b)))
        return out


def _stats(v: np.ndarray) -> dict[str, float]:
    return {"mean": float(np.mean(v)), "median": float(np.median(v)), "max": float(np.max(v))}


def compare(a: Saved, b: Saved) -> Comparison:
    """Match the rows of ``a`` and ``b``; EvalError when they have no row in common."""
    ra, rb = {key(r): r for r in a.rows}, {key(r): r for r in b.rows}
    cmp = Comparison(a, b)
    cmp.pairs = [Pair(k, ra[k].rmse_deg, rb[k].rmse_deg) for k in ra if k in rb]
    cmp.only_a = [k for k in ra if k not in rb]
    cmp.only_b = [k for k in rb if k not in ra]
    if not cmp.pairs:
        raise EvalError(f"{a.path} and {b.path} have no result in common (same sequence, scenario, perturbation, "
                        "rate and estimator)")
    return cmp


def _rate(rate: str | float) -> str:
    return str(rate) if rate == NATIVE else f"{float(rate):g} Hz"


def _table(headers: list[str], rows: list[list[str]], numeric: set[str]) -> list[str]:
    widths = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(headers)]

    def fmt(row: list[str]) -> str:
        return "  ".join(c.rjust(w) if h in numeric else c.ljust(w) for c, w, h in zip(row, widths, headers,
                                                                                       strict=True))

    return [fmt(headers), "  ".join("-" * w for w in widths), *(fmt(r) for r in rows)]


def format_comparison(cmp: Comparison) -> str:
    """The text of ``--compare``: per group, then per sequence; B − A, negative = B better."""
    groups = cmp.groups()
    prt = len({g.perturbation for g in groups}) > 1 or any(g.perturbation != NONE for g in groups)
    multi = len({g.rate for g in groups}) > 1
    head = ["estimator", "scenario", *(["perturbation"] if prt else []), *(["rate"] if multi else []), "n"]
    stats = ("mean", "median", "max")
    headers = head + [f"{s} {x}" for s in stats for x in ("A", "B", "B-A")]
    rows = [
        [g.estimator, g.scenario, *([g.perturbation] if prt else []), *([_rate(g.rate)] if multi else []), str(g.n)]
        + [f"{v:+.2f}" if x == "B-A" else f"{v:.2f}" for s in stats
           for x, v in (("A", g.a[s]), ("B", g.b[s]), ("B-A", g.diff(s)))]
        for g in groups
    ]
    numeric = {"n", *headers[len(head):]}
    out = [f"A = {cmp.a.label}: {cmp.a.path}" + (f"  ({cmp.a.command})" if cmp.a.command else ""),
           f"B = {cmp.b.label}: {cmp.b.path}" + (f"  ({cmp.b.command})" if cmp.b.command else ""), "",
           "attitude RMSE e_α (°) per sequence, B − A (negative: B is better)",
           *_table(headers, rows, numeric), "", "per sequence"]
    seq_rows = [[p.key[4], p.key[1], *([p.key[2]] if prt else []), *([_rate(p.key[3])] if multi else []), p.key[0],
                 f"{p.a:.2f}", f"{p.b:.2f}", f"{p.diff:+.2f}"] for p in _ordered(cmp)]
    out += _table([*head[:-1], "sequence", "A", "B", "B-A"], seq_rows, {"A", "B", "B-A"})
    out += format_uncertainty_comparison(cmp.a.rows, cmp.b.rows)
    for name, keys in (("A", cmp.only_a), ("B", cmp.only_b)):
        if keys:
            shown = ", ".join(_key_text(k) for k in keys[:5]) + (" …" if len(keys) > 5 else "")
            out.append(f"only in {name} (not compared): {len(keys)} row(s): {shown}")
    return "\n".join(out)


def _key_text(k: Key) -> str:
    """``sequence/scenario[/perturbation][/rate]/estimator``."""
    seq, scn, prt, rate, est = k
    return "/".join([seq, scn, *([prt] if prt != NONE else []), *([_rate(rate)] if rate != NATIVE else []), est])


def _ordered(cmp: Comparison) -> list[Pair]:
    order = {(g.estimator, g.scenario, g.perturbation, g.rate): i for i, g in enumerate(cmp.groups())}
    return sorted(cmp.pairs, key=lambda p: order[(p.key[4], p.key[1], p.key[2], p.key[3])])


def write_csv(path: Path, cmp: Comparison) -> None:
    """compare.csv: one row per matched sequence × scenario × perturbation × rate × estimator."""
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["sequence", "scenario", "perturbation", "rate", "estimator", "rmse_a_deg", "rmse_b_deg",
                    "diff_deg"])
        for p in _ordered(cmp):
            seq, scn, prt, rate, est = p.key
            w.writerow([seq, scn, prt, rate, est, f"{p.a:.6f}", f"{p.b:.6f}", f"{p.diff:.6f}"])


def differences(cmp: Comparison) -> dict[tuple[str, str, str | float, str], list[float]]:
    """(scenario, perturbation, rate, estimator) -> the per-sequence differences B − A, in table order."""
    return {(g.scenario, g.perturbation, g.rate, g.estimator):
            [p.diff for p in cmp.pairs if p.key[1:] == (g.scenario, g.perturbation, g.rate, g.estimator)]
            for g in cmp.groups()}


def write_comparison(out: Path, cmp: Comparison, plots: bool = True, replace: bool = False) -> list[Path]:
    """compare.csv and (``plots``) compare_rmse.png/.svg in ``out`` (the --out policy of
    :func:`~riann_ros.evaluation.outdir.prepare_out`); returns the files written."""
    prepare_out(out, replace)
    written = [out / "compare.csv"]
    try:
        write_csv(written[0], cmp)
        if plots:
            written += pl.plot_differences(differences(cmp), cmp.a.label, cmp.b.label, out)
    except BaseException:
        for f in written:
            f.unlink(missing_ok=True)
        raise
    return written
