"""Accuracy of every estimator on the BROAD trials under realistic perturbations.

Usage::

    .venv/bin/python bench/bench_accuracy.py [--jobs 2] [--out DIR] [--estimators SPECS]

Runs ``riann-bag-eval`` on the BROAD trial files (``$RIANN_BROAD_DIR`` or ``../shared/datasets/broad``):

1. scenarios ``as-recorded`` (the recording as it is, from its first sample) and ``realistic`` (from the motion
   onset), one run each, under the conditions ``none``, ``jitter:10/20/30ms`` (interval means),
   ``jitter:10/20/30ms:points`` and ``jitter:5-15ms:points`` (point samples at random times), ``jitter:2-8ms``,
   ``latency:0-10ms``, ``fifo:20ms``, regular streams at 25, 50 and 100 Hz made three ways (``rate:HZ`` interval
   means stamped at the end, ``rate:HZ:points`` the signal at the stamp, ``rate:HZ:lowpass`` a first-order
   low-pass of time constant half a step at the stamp), ``bias:3,3,0``, ``bias:random:2``,
   ``dropout:0.1-0.6s@10s``, ``dropout:0.01-0.05s@1s`` (a few messages lost about once a second) and
   ``latency:0-10ms+dropout:0.01-0.05s@1s`` (the same on a stream stamped on arrival);
2. the as-recorded scenario FFT-resampled to 25, 50, 100, 200, 500 and 1000 Hz (``--rates``).

Prints markdown: mean / worst RMSE (°) per condition and estimator, the dropout rows also on the six trials with
movement throughout (02, 07, 10, 15, 24, 27), and RIANN's per-trial ratio to its native-rate RMSE for every rate.
The pages' tables (README, docs/results.md, BENCHMARKS.md) are written by ``bench/results_tables.py`` from the
results.json files ``--out`` keeps, committed trimmed under docs/results/ (docs/results/README.md).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

from riann_ros.cli.evaluate import main as eval_main
from riann_ros.datasets.broad import broad_files, find_broad_dir

ESTIMATORS = "riann,vqf,madgwick,mahony"
REGULAR = tuple(f"rate:{hz}{kind}" for hz in (25, 50, 100) for kind in ("", ":points", ":lowpass"))
CONDITIONS = ("none", "jitter:10/20/30ms", "jitter:10/20/30ms:points", "jitter:2-8ms", "jitter:5-15ms:points",
              "latency:0-10ms", "fifo:20ms", *REGULAR, "bias:3,3,0", "bias:random:2", "dropout:0.1-0.6s@10s",
              "dropout:0.01-0.05s@1s", "latency:0-10ms+dropout:0.01-0.05s@1s")
RATES = "25,50,100,200,500,1000"
SCENARIOS = ("as-recorded", "realistic")
DROPOUT_TRIALS = ("02", "07", "10", "15", "24", "27")


def run(argv: list[str], out: Path) -> list[dict]:
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        # these tables are 6D: the BROAD files carry a magnetometer, which --use-mag auto would use
        rc = eval_main([*argv, "--use-mag", "false", "--out", str(out), "--no-plots", "-q", "--force"])
    if rc:
        print(buf.getvalue(), file=sys.stderr)
        raise SystemExit(f"riann-bag-eval exited {rc}")
    return json.loads((out / "results.json").read_text())["results"]


def stats(rows: list[dict], **match: str) -> dict[str, tuple[float, float, int]]:
    """estimator -> (mean, worst, n) of the rows matching ``match``."""
    out: dict[str, list[float]] = {}
    for r in rows:
        if all(r[k] == v for k, v in match.items()):
            out.setdefault(r["estimator"], []).append(r["rmse_deg"])
    return {k: (sum(v) / len(v), max(v), len(v)) for k, v in out.items()}


def table(rows: list[dict], estimators: list[str], scenario: str, trials: tuple[str, ...] | None = None) -> str:
    sel = [r for r in rows if r["scenario"] == scenario and (trials is None or r["sequence"][:2] in trials)]
    lines = ["| condition | " + " | ".join(estimators) + " |", "|---|" + "---:|" * len(estimators)]
    for cond in dict.fromkeys(r["perturbation"] for r in sel):
        s = stats(sel, perturbation=cond)
        cells = [f"{s[e][0]:.2f} / {s[e][1]:.2f}" if e in s else "–" for e in estimators]
        lines.append(f"| {cond} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def rate_ratios(rows: list[dict], native: list[dict], estimator: str) -> str:
    base = {r["sequence"]: r["rmse_deg"] for r in native if r["estimator"] == estimator}
    rates = sorted({r["rate"] for r in rows if isinstance(r["rate"], float)})
    lines = ["| trial | native ° | " + " | ".join(f"{f:g} Hz" for f in rates) + " |",
             "|---|---:|" + "---:|" * len(rates)]
    worst = dict.fromkeys(rates, 0.0)
    for seq, b in base.items():
        cells = []
        for f in rates:
            v = next(r["rmse_deg"] for r in rows
                     if (r["sequence"], r["rate"], r["estimator"]) == (seq, f, estimator))
            worst[f] = max(worst[f], v / b)
            cells.append(f"{v:.2f} ({v / b:.2f}×)")
        lines.append(f"| {seq[:2]} | {b:.2f} | " + " | ".join(cells) + " |")
    lines.append("| worst ratio | | " + " | ".join(f"{worst[f]:.2f}×" for f in rates) + " |")
    return "\n".join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--estimators", default=ESTIMATORS)
    ap.add_argument("--out", type=Path, default=None, help="keep the evaluator's outputs here")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    d = find_broad_dir()
    if d is None:
        print("BROAD not found (set RIANN_BROAD_DIR)", file=sys.stderr)
        return 1
    inputs = [str(p) for p in broad_files(d)]
    out = args.out or Path(tempfile.mkdtemp(prefix="bench_accuracy_"))
    ests = [e.split(":")[0] if ":" not in e else e for e in args.estimators.split(",")]
    common = [*inputs, "-e", args.estimators, "--seed", str(args.seed), "--jobs", str(args.jobs)]
    t0 = time.perf_counter()
    # one run per scenario: the same rows as one run of both, in half the memory per worker (a worker holds every
    # condition × scenario of its trial at once)
    perturbed = [row for scenario in SCENARIOS
                 for row in run([*common, "-s", scenario, *(a for c in CONDITIONS for a in ("-p", c))],
                                out / f"perturbed-{scenario}")]
    rated = run([*common, "-s", "as-recorded", "--rates", RATES], out / "rates")
    wall = time.perf_counter() - t0
    labels = list(dict.fromkeys(r["estimator"] for r in perturbed)) or ests
    print(f"## Accuracy under perturbations: {len(inputs)} BROAD trials, seed {args.seed}\n")
    print(f"- commands: `riann-bag-eval <trials> -e {args.estimators} -s as-recorded,realistic "
          + " ".join(f"-p {c}" for c in CONDITIONS) + f" --seed {args.seed} --use-mag false` and `riann-bag-eval "
          f"<trials> -e {args.estimators} -s as-recorded --rates {RATES} --use-mag false`")
    print(f"- {wall:.0f} s wall on {os.cpu_count()} CPUs ({platform.machine()}), --jobs {args.jobs}\n")
    print("### as-recorded (from the first sample, turn-on bias kept): mean / worst RMSE °\n")
    print(table(perturbed, labels, "as-recorded"))
    print("\n### realistic (from the motion onset, paper's random bias): mean / worst RMSE °\n")
    print(table(perturbed, labels, "realistic"))
    print(f"\n### dropouts on trials {', '.join(DROPOUT_TRIALS)} (as-recorded): mean / worst RMSE °\n")
    print(table([r for r in perturbed if r["perturbation"] in ("none", "dropout:0.1-0.6s@10s")], labels,
                "as-recorded", DROPOUT_TRIALS))
    native = [r for r in perturbed if r["scenario"] == "as-recorded" and r["perturbation"] == "none"]
    print("\n### FFT-resampled rates (as-recorded), RIANN per trial (ratio to its native-rate RMSE)\n")
    print(rate_ratios(rated, native, labels[0]))
    print("\n### FFT-resampled rates (as-recorded): mean / worst RMSE °\n")
    rates = sorted({r["rate"] for r in rated if isinstance(r["rate"], float)})
    lines = ["| rate | " + " | ".join(labels) + " |", "|---|" + "---:|" * len(labels)]
    for f in rates:
        s = stats([r for r in rated if r["rate"] == f])
        lines.append(f"| {f:g} Hz | " + " | ".join(f"{s[e][0]:.2f} / {s[e][1]:.2f}" for e in labels) + " |")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
