"""Benchmark of riann-bag-eval's executors: the same run in-process, with ``--jobs 2`` and on a local Dask cluster
(``--scheduler local:2``), back to back on one machine; and a corpus of many short inputs (``--inputs-from``) for the
per-input cost of the cluster path and the client's memory.

Usage::

    .venv/bin/python bench/bench_cluster.py                  # held-out-sized run, 1 round, and 1000 short inputs
    .venv/bin/python bench/bench_cluster.py --rounds 3 --many 0
    .venv/bin/python bench/bench_cluster.py --rounds 0 --many 1000,200
    .venv/bin/python bench/bench_cluster.py --rounds 2 --many 1000 --save   # the figures of BENCHMARKS.md

``--save`` writes the figures into ``docs/results/cluster.json`` (with the command, the machine and the load
averages), from which ``bench/results_tables.py`` writes the ``cluster-*`` blocks of BENCHMARKS.md and
docs/evaluation.md ("Scaling out": the 10 000-bag extrapolation).

**Held-out-sized run**: the 12 BROAD trials (``$RIANN_BROAD_DIR`` or ``../shared/datasets/broad``) × 4 estimators ×
the paper's 3 scenarios (``-e riann,madgwick,mahony,vqf -s paper --seed 0 --no-plots``), each mode a whole
``riann-bag-eval`` process timed from outside, the modes in turn (in-process, --jobs 2, local:2) for each round; the
ratio local:2 / --jobs 2 is taken round by round. The 1-min load average before and after each run is printed (the
machine may be shared). Every mode's rows are checked equal to the in-process rows (RMSE within 1e-9°).

**Many inputs**: N symbolic links to one 10 s, 100 Hz synthetic bag listed in a file, ``-e madgwick -s as-recorded
--offset-steps 0`` with --out (shards, report, plots), on local:2 and with --jobs 2: wall time, time per input, the
client process's peak resident set (its own ``RUSAGE_SELF``: the cluster's workers are other processes), and the
bytes kept per input (shards, results.json).

Prints markdown tables.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from riann_ros.datasets.broad import broad_files, find_broad_dir, read_broad

BIN = Path(sys.executable).parent
SAVE = Path(__file__).resolve().parents[1] / "docs" / "results" / "cluster.json"
HELD_OUT = ["-e", "riann,madgwick,mahony,vqf", "-s", "paper", "--seed", "0", "--no-plots", "-q"]
MODES = {"in-process": ["--jobs", "1"], "--jobs 2": ["--jobs", "2"], "--scheduler local:2": ["--scheduler", "local:2"]}
# the client's own peak (VmHWM: ru_maxrss would carry the launching process's peak over fork and exec)
CLIENT = """
import re, sys
from riann_ros.cli.evaluate import main
code = main(sys.argv[2:])
with open("/proc/self/status") as status, open(sys.argv[1], "w") as f:
    f.write(re.search(r"VmHWM:\\s+(\\d+) kB", status.read()).group(1))
sys.exit(code)
"""


def load() -> float:
    return os.getloadavg()[0]


def children_cpu() -> float:
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def timed(cmd: list[str]) -> tuple[float, float, float, float]:
    """Wall seconds of a whole process, the 1-min load average before and after, and the CPU seconds the operating
    system accounts to it: the whole run in-process; without the workers of a pool or cluster, which are children of a
    fork server or nanny that is not waited for."""
    before, cpu = load(), children_cpu()
    t = time.perf_counter()
    r = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    wall = time.perf_counter() - t
    if r.returncode != 0:
        raise SystemExit(f"failed ({r.returncode}): {' '.join(cmd)}\n{r.stderr[-2000:]}")
    return wall, before, load(), children_cpu() - cpu


def rmse(out: Path) -> list[tuple[str, float]]:
    with open(out / "results.csv") as f:
        return [(f"{r['sequence']}/{r['scenario']}/{r['estimator']}", float(r["rmse_deg"])) for r in csv.DictReader(f)]


def recorded_s(trials: list[str]) -> float:
    """Seconds of recording in the trials."""
    total = 0.0
    for p in trials:
        stamps = read_broad(p).stamps_ns
        total += (int(stamps[-1]) - int(stamps[0])) / 1e9
    return total


def held_out(rounds: int, work: Path) -> dict | None:
    d = find_broad_dir()
    if d is None:
        print("held-out-sized run skipped: the BROAD trials are not here (set RIANN_BROAD_DIR)")
        return None
    trials = [str(p) for p in broad_files(d)]
    walls: dict[str, list[float]] = {m: [] for m in MODES}
    loads: dict[str, list[tuple[float, float]]] = {m: [] for m in MODES}
    cpus: dict[str, list[float]] = {m: [] for m in MODES}
    worst = 0.0
    for k in range(rounds):
        ref = None
        for mode, extra in MODES.items():
            out = work / f"held_{k}_{mode.replace(' ', '_').replace(':', '')}"
            wall, before, after, cpu = timed([str(BIN / "riann-bag-eval"), *trials, *HELD_OUT, *extra, "--out",
                                              str(out)])
            walls[mode].append(wall)
            cpus[mode].append(cpu)
            loads[mode].append((before, after))
            rows = rmse(out)
            ref = ref or rows
            assert [r[0] for r in rows] == [r[0] for r in ref], f"{mode}: other rows"
            worst = max(worst, *(abs(a[1] - b[1]) for a, b in zip(rows, ref, strict=True)))
            print(f"round {k + 1} {mode}: {wall:.1f} s, CPU {cpu:.1f} s (load {before:.1f} / {after:.1f})",
                  file=sys.stderr)
    n_rows = len(ref or [])
    print(f"\n{len(trials)} trials × 4 estimators × 3 scenarios ({n_rows} rows); {rounds} round(s), modes in turn; "
          f"rows of every mode equal the in-process rows (largest RMSE difference {worst:.1e}°)\n")
    print("| mode | wall time per round (s) | median (s) | 1-min load average before / after |")
    print("|---|---|---:|---|")
    for mode in MODES:
        runs = ", ".join(f"{w:.1f}" for w in walls[mode])
        ld = ", ".join(f"{a:.1f} / {b:.1f}" for a, b in loads[mode])
        print(f"| {mode} | {runs} | {statistics.median(walls[mode]):.1f} | {ld} |")
    ratios = [c / j for c, j in zip(walls["--scheduler local:2"], walls["--jobs 2"], strict=True)]
    print(f"\nlocal:2 / --jobs 2, round by round: {', '.join(f'{r:.2f}' for r in ratios)} "
          f"(median {statistics.median(ratios):.2f})")
    return {"trials": len(trials), "rows": n_rows, "recorded_s": round(recorded_s(trials), 1),
            "max_rmse_diff_deg": worst, "walls_s": {m: [round(w, 2) for w in ws] for m, ws in walls.items()},
            "cpu_s": {m: [round(c, 2) for c in cs] for m, cs in cpus.items()},
            "loads": {m: [[round(a, 2), round(b, 2)] for a, b in ls] for m, ls in loads.items()}}


def many(n: int, work: Path) -> list[dict]:
    from riann_ros import bagio
    from riann_ros.datasets.synthetic import generate

    corpus = work / f"many_{n}"
    corpus.mkdir()
    tiny = bagio.write_recording(corpus / "tiny.mcap", generate(rate=100, duration=10, seed=1, start_s=1.0))
    names = [f"r{k:05d}.mcap" for k in range(n)]
    for name in names:
        (corpus / name).hardlink_to(tiny)  # files of their own paths (links to one file are one input)
    (corpus / "list.txt").write_text("\n".join(names) + "\n")
    print(f"\n{n} inputs (links to one 10 s, 100 Hz bag), -e madgwick -s as-recorded --offset-steps 0, --out\n")
    print("| mode | wall s | ms per input | client peak RSS MB | shards KB per input | results.json KB per input | "
          "1-min load before / after |")
    print("|---|---:|---:|---:|---:|---:|---|")
    rows = []
    for mode, extra in (("--scheduler local:2", ["--scheduler", "local:2"]), ("--jobs 2", ["--jobs", "2"])):
        out, peak = corpus / f"out_{extra[-1].replace(':', '')}", corpus / f"peak_{extra[-1].replace(':', '')}"
        wall, before, after, cpu = timed([sys.executable, "-c", CLIENT, str(peak), "--inputs-from",
                                          str(corpus / "list.txt"), "-e", "madgwick", "-s", "as-recorded",
                                          "--offset-steps", "0", "-q", *extra, "--out", str(out)])
        shards = sum(p.stat().st_size for p in (out / "shards").glob("*.npz"))
        print(f"| {mode} | {wall:.1f} | {1000 * wall / n:.0f} | {int(peak.read_text()) / 1024:.0f} | "
              f"{shards / n / 1024:.1f} | {(out / 'results.json').stat().st_size / n / 1024:.1f} | "
              f"{before:.1f} / {after:.1f} |")
        rows.append({"mode": mode, "inputs": n, "wall_s": round(wall, 2), "cpu_s": round(cpu, 2), "client_peak_rss_mb":
                     round(int(peak.read_text()) / 1024, 1), "shards_bytes_per_input": round(shards / n),
                     "results_json_bytes_per_input": round((out / "results.json").stat().st_size / n),
                     "load": [round(before, 2), round(after, 2)]})
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rounds", type=int, default=1, help="rounds of the held-out-sized run (0: none)")
    ap.add_argument("--many", default="1000", help="comma-separated corpus sizes of short inputs (0: none)")
    ap.add_argument("--save", action="store_true", help=f"write the figures into {SAVE.relative_to(SAVE.parents[2])}")
    args = ap.parse_args()
    machine = f"{os.cpu_count()} cores, {platform.machine()}, Python {platform.python_version()}"
    print(f"machine: {machine}; 1-min load average at start {load():.1f}")
    saved: dict = {"command": "bench/bench_cluster.py " + " ".join(sys.argv[1:]), "machine": machine,
                   "held_out_args": " ".join(HELD_OUT), "held_out": None, "many": []}
    with tempfile.TemporaryDirectory(prefix="bench_cluster_") as tmp:
        if args.rounds > 0:
            saved["held_out"] = held_out(args.rounds, Path(tmp))
        for n in (int(x) for x in args.many.split(",") if x.strip()):
            if n > 0:
                saved["many"] += many(n, Path(tmp))
    if args.save:
        SAVE.write_text(json.dumps(saved, indent=1) + "\n")
        print(f"wrote {SAVE} (bench/results_tables.py writes the pages)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
