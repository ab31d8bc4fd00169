"""Benchmark of riann-bag-eval: the 12 BROAD trials × 4 estimators × 3 scenarios, offline, ``--jobs 2``.

Usage::

    .venv/bin/python bench/bench_eval.py [--jobs 2] [--bags DIR_OR_FILES...] [--out DIR]

Without ``--bags`` the BROAD trial files (``$RIANN_BROAD_DIR`` or ``../shared/datasets/broad``) are
read directly (same numbers as their converted bags). Prints the wall time, the summary table and the
samples per second per estimator (CPU time of each estimator run through the node's EstimatorStream,
input gate included, summed over all runs) as markdown for BENCHMARKS.md.
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
from riann_ros.evaluation import Group
from riann_ros.evaluation.report import format_markdown_table

ESTIMATORS = "riann,madgwick:beta=0.033,mahony:kp=1:ki=0.3,vqf"


def gate_rate() -> float:
    """Samples/s of the node's per-sample input gate alone, which every estimator run goes through."""
    from riann_ros.stream import GateConfig, InputGate

    d = find_broad_dir()
    if d is None:
        return float("nan")
    from riann_ros.datasets.broad import read_broad

    rec = read_broad(broad_files(d)[0])
    gate = InputGate(GateConfig(nominal_rate=rec.rate_hz))
    stamps = rec.stamps_ns + 1_000_000_000
    t = time.perf_counter()
    for i in range(len(rec)):
        gate.check(int(stamps[i]), rec.acc[i], rec.gyr[i])
    return len(rec) / (time.perf_counter() - t)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--bags", nargs="*", default=None, help="inputs (default: the BROAD trial files)")
    ap.add_argument("--estimators", default=ESTIMATORS)
    ap.add_argument("--out", type=Path, default=None, help="keep the evaluator's output here")
    args = ap.parse_args()
    if args.bags:
        inputs = [str(p) for p in args.bags]
    else:
        d = find_broad_dir()
        if d is None:
            print("BROAD not found (set RIANN_BROAD_DIR)", file=sys.stderr)
            return 1
        inputs = [str(p) for p in broad_files(d)]
    out = args.out or Path(tempfile.mkdtemp(prefix="bench_eval_"))
    argv = [
        *inputs,
        "--estimators",
        args.estimators,
        "--scenarios",
        "paper",
        "--seed",
        "0",
        "--jobs",
        str(args.jobs),
        "--out",
        str(out),
        "--no-plots",
        "-q",
        "--force",
    ]
    load_before = os.getloadavg()[0]
    t0 = time.perf_counter()
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        rc = eval_main(argv)
    wall = time.perf_counter() - t0
    data = json.loads((out / "results.json").read_text())
    rows = data["results"]
    per: dict[str, list[float]] = {}
    for r in rows:
        acc = per.setdefault(r["estimator"], [0.0, 0.0, 0.0])
        acc[0] += r["seconds"]
        acc[1] += r["n_samples"]
        acc[2] += r.get("cpu_seconds", float("nan"))
    cpu_total = sum(v[2] for v in per.values())
    cpu_seq = sum(s.get("cpu_seconds", 0.0) for s in data["sequences"])
    cmd = "riann-bag-eval <12 BROAD trials> " + " ".join(argv[len(inputs) :])
    print(f"## riann-bag-eval, {len(inputs)} inputs, jobs {args.jobs}\n")
    print(f"- command: `{cmd}` (exit {rc})")
    print(
        f"- wall time: **{wall:.1f} s** on {os.cpu_count()} CPUs, {platform.processor() or platform.machine()}, "
        f"1-min load average before/after: {load_before:.2f} / {os.getloadavg()[0]:.2f}"
    )
    print(f"- runs: {len(rows)} (sequence × scenario × estimator), samples: {sum(v[1] for v in per.values()):.0f}")
    print(
        f"- CPU time of all estimator runs: {cpu_total:.1f} s, i.e. {cpu_total / args.jobs:.1f} s per worker "
        f"(the wall time on {args.jobs} otherwise idle cores, plus start-up and reading)"
    )
    print(
        f"- CPU time of the workers (reading, scenarios, runs, scoring): {cpu_seq:.1f} s, i.e. "
        f"{cpu_seq / args.jobs:.1f} s per worker"
    )
    print("\n| estimator | runs wall s | runs CPU s | samples/s per core (CPU; gate + estimator) |")
    print("|---|---:|---:|---:|")
    for k, (secs, n, cpu) in per.items():
        print(f"| {k} | {secs:.1f} | {cpu:.1f} | {n / cpu:,.0f} |")
    print(f"\ninput gate alone (InputGate.check per sample, in-process, one trial): {gate_rate():,.0f} samples/s")
    print()
    print(format_markdown_table([Group(**g) for g in data["summary"]]))
    return rc


if __name__ == "__main__":
    sys.exit(main())
