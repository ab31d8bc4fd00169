"""Per-sample ``RiannEstimator.update`` cost (the node's path: one call per message), A/B against another version.

Usage::

    .venv/bin/python bench/bench_update.py [--ref DIR] [--rounds 3] [--samples 6000] [--ensemble 4,1] [--mag OFFSET]
        [--estimators riann,consensus]

Streams (a 1 Hz swing, gyro bias 0): 200 Hz and 1 kHz regular, 200 Hz stamped on arrival (0-10 ms delivery
delays: the clock stage de-jitters), and jittery 5-15 ms steps (the sample-model test runs). Each figure is the
best of ``--rounds`` runs of ``--samples`` calls, in a fresh process per run; with ``--ref`` (a checkout of
another version, e.g. ``git worktree add /tmp/ref <commit>``) the two versions alternate in one session, so the
ratio is measured on the same machine state. ONNX Runtime runs with one thread. ``--mag X,Y,Z`` (µT) passes a
magnetometer field (9D: a 50 µT field seen through the swing, plus that hard-iron offset; ``0,0,0``: a calibrated
sensor), so the online magnetometer calibration runs where the version has one (its default parameters; where the
calibration is the stream's magnetometer front end, the estimator is given one as the stream gives it).
``--estimators`` times other estimators that take ``ensemble`` (RIANN's parameters: ``consensus``) beside it, in the
same session, alternating like the versions.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
STREAMS = ("200 Hz", "1 kHz", "200 Hz on arrival", "jittery 5-15 ms")

CHILD = r"""
import json, math, sys, time
import numpy as np
from riann_ros.estimators import create
STREAMS = ("200 Hz", "1 kHz", "200 Hz on arrival", "jittery 5-15 ms")
n, copies, name = int(sys.argv[1]), int(sys.argv[2]), sys.argv[4]
off = None if sys.argv[3] == "-" else np.array([float(v) for v in sys.argv[3].split(",")]) * 1e-6
rng = np.random.default_rng(0)
def steps(kind):
    if kind == "200 Hz": return np.full(n, 0.005)
    if kind == "1 kHz": return np.full(n, 0.001)
    if kind == "200 Hz on arrival":
        t = 0.005 * np.arange(1, n + 1) + rng.uniform(0, 0.010, n)
        t = np.maximum.accumulate(t - 1e-6 * np.arange(n)) + 1e-6 * np.arange(n)
        return np.diff(np.concatenate([[0.0], t]))
    return rng.uniform(0.005, 0.015, n)
out = {}
for kind in STREAMS:
    dt = steps(kind)
    t = np.cumsum(dt)
    roll = 0.5 * np.sin(2 * math.pi * t)
    acc = np.column_stack([np.zeros(n), 9.81 * np.sin(roll), 9.81 * np.cos(roll)])
    gyr = np.column_stack([np.pi * np.cos(2 * math.pi * t), np.zeros(n), np.zeros(n)])
    est = create(name, ensemble=copies)
    if off is not None and hasattr(est, "take_front_end"):  # the magnetometer's front end, as the stream gives it
        from riann_ros.magcal.frontend import FrontEndConfig, MagFrontEnd
        est.take_front_end(MagFrontEnd(FrontEndConfig.of(est.params), latency=est.front_end_latency()))
    a, g, d = acc.tolist(), gyr.tolist(), dt.tolist()
    if off is None:
        m = [None] * n
    else:  # the world field (0, 20, -40) µT seen by the sensor rolled about x, plus the offset
        mf = np.column_stack([np.zeros(n), 20e-6 * np.cos(roll) - 40e-6 * np.sin(roll),
                              -20e-6 * np.sin(roll) - 40e-6 * np.cos(roll)]) + off
        m = mf.tolist()
    t0 = time.perf_counter()
    for i in range(n):
        est.update(a[i], g[i], d[i], m[i])
    out[kind] = (time.perf_counter() - t0) / n * 1e6
print(json.dumps(out))
"""


def run(tree: Path, n: int, copies: int, mag: str, estimator: str) -> dict[str, float]:
    env = dict(os.environ, PYTHONPATH=str(tree), OMP_NUM_THREADS="1")
    r = subprocess.run([sys.executable, "-c", CHILD, str(n), str(copies), mag, estimator], env=env,
                       capture_output=True, text=True, check=True)
    return json.loads(r.stdout.strip().splitlines()[-1])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ref", type=Path, default=None, help="another checkout to compare with")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--samples", type=int, default=6000)
    ap.add_argument("--ensemble", default="4,1")
    ap.add_argument("--mag", default="-", metavar="X,Y,Z", help="µT; 9D with this hard-iron offset (default: 6D)")
    ap.add_argument("--estimators", default="riann", help="estimators to time (RIANN's parameters: riann, consensus)")
    args = ap.parse_args()
    roots = {"this": ROOT} | ({"ref": args.ref.resolve()} if args.ref else {})
    names = args.estimators.split(",")
    trees = {(f"{t} {e}" if len(names) > 1 else t): (tree, e) for t, tree in roots.items() for e in names}
    best: dict[tuple[str, int, str], float] = {}
    for _ in range(args.rounds):
        for copies in (int(c) for c in args.ensemble.split(",")):
            for name, (tree, estimator) in trees.items():
                for kind, us in run(tree, args.samples, copies, args.mag, estimator).items():
                    key = (name, copies, kind)
                    best[key] = min(best.get(key, float("inf")), us)
    print(f"per-sample update(), µs, best of {args.rounds} × {args.samples} calls")
    cols = [f"{n} ×{c}" for c in (int(c) for c in args.ensemble.split(",")) for n in trees]
    print("| stream | " + " | ".join(cols) + " |")
    print("|---|" + "---:|" * len(cols))
    for kind in STREAMS:
        cells = [f"{best[(n, c, kind)]:.0f}" for c in (int(c) for c in args.ensemble.split(",")) for n in trees]
        print(f"| {kind} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
