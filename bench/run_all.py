"""Run every benchmark in bench/ once, in a short form, and print their reports (``make bench``).

Usage::

    .venv/bin/python bench/run_all.py [--full] [--only NAME[,NAME...]]

Short form (default, about 10 minutes on 2 cores): each benchmark with reduced durations, enough to see
that it runs and roughly where the figures are. ``--full`` runs each with its own defaults (the
durations BENCHMARKS.md quotes; hours for the soak runs). Benchmarks that need the BROAD trials
(``$RIANN_BROAD_DIR`` or ``../shared/datasets/broad``) are skipped with a note when they are absent.
DDS traffic stays on this machine (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``, a domain of its own).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

from riann_ros.datasets.broad import find_broad_dir

HERE = Path(__file__).resolve().parent

# name -> (script, short arguments, needs BROAD)
BENCHES: dict[str, tuple[str, list[str], bool]] = {
    "filters": ("bench_filters.py", ["--repeat", "1"], True),
    "eval": ("bench_eval.py", ["--jobs", "2"], True),
    "accuracy": ("bench_accuracy.py", ["--jobs", "2"], True),
    "bags": ("bench_bags.py", ["--duration", "60"], False),
    "long_bag": ("bench_long_bag.py", ["--durations", "120", "--no-stream"], False),
    "network": ("bench_network.py", ["--reps", "3", "--trial", "07", "--steps", "500"], False),
    "node": ("bench_node.py", ["--rates", "200,1000", "--duration", "10"], False),
    "soak": ("soak_nodes.py", ["--rates", "1000", "--duration", "20", "--probe-rates", "2000", "--probe-duration",
                               "10", "--side-by-side-duration", "20"], False),
}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--full", action="store_true", help="each benchmark with its own (long) defaults")
    ap.add_argument("--only", default="", help=f"comma-separated subset of {', '.join(BENCHES)}")
    args = ap.parse_args()
    names = [n.strip() for n in args.only.split(",") if n.strip()] or list(BENCHES)
    unknown = set(names) - set(BENCHES)
    if unknown:
        ap.error(f"unknown benchmark(s) {', '.join(sorted(unknown))}; known: {', '.join(BENCHES)}")
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    env.setdefault("ROS_DOMAIN_ID", "58")
    broad = find_broad_dir() is not None
    failed = []
    for name in names:
        script, short, needs_broad = BENCHES[name]
        if not (HERE / script).is_file():
            continue
        print(f"\n===== {name}: bench/{script} {' '.join([] if args.full else short)}", flush=True)
        if needs_broad and not broad:
            print("skipped: the BROAD trials are not here (set RIANN_BROAD_DIR)")
            continue
        t0 = time.perf_counter()
        rc = subprocess.call([sys.executable, str(HERE / script), *([] if args.full else short)], env=env)
        print(f"----- {name}: exit {rc}, {time.perf_counter() - t0:.0f} s", flush=True)
        if rc:
            failed.append(name)
    if failed:
        print(f"\nfailed: {', '.join(failed)}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
