"""RIANN's attitude on a few BROAD trials and conditions, to compare two versions of the code (e.g. before and after
a change that must not move the attitude).

    RIANN_BROAD_DIR=... PYTHONPATH=<checkout A> python bench/attitude_diff.py run a.npz
    RIANN_BROAD_DIR=... PYTHONPATH=<checkout B> python bench/attitude_diff.py run b.npz
    python bench/attitude_diff.py diff a.npz b.npz

Trials 01, 21 and 30 through EstimatorStream.process_batch: as recorded, with a dropout of 0.1–0.35 s every 10 s,
with a gyro bias of (3, 3, 0) °/s, and in 9D (the trial's magnetometer). The estimates derive from BROAD: keep the
.npz files outside the repository.
"""

from __future__ import annotations

import sys

import numpy as np

from riann_ros.datasets.broad import broad_files, find_broad_dir, read_broad
from riann_ros.estimators import create
from riann_ros.stream import EstimatorStream, GateConfig

TRIALS = ("01", "21", "30")
CONDITIONS = ("none", "dropout", "bias", "mag")


def run(out: str) -> None:
    d = find_broad_dir()
    if d is None:
        sys.exit("no BROAD trials: set RIANN_BROAD_DIR")
    res = {}
    for p in broad_files(d):
        if p.name[:2] not in TRIALS:
            continue
        rec = read_broad(p)
        t = (rec.stamps_ns - rec.stamps_ns[0]) * 1e-9
        for cond in CONDITIONS:
            keep = np.ones(len(t), bool)
            gyr = rec.gyr.copy()
            if cond == "dropout":
                for k, t0 in enumerate(np.arange(10.0, t[-1], 10.0)):
                    keep &= ~((t >= t0) & (t < t0 + 0.1 + 0.25 * (k % 3) / 2))
            if cond == "bias":
                gyr += np.radians([3.0, 3.0, 0.0])
            mag = rec.mag[keep] if cond == "mag" and rec.mag is not None else None
            s = EstimatorStream(create("riann"), GateConfig(nominal_rate=rec.rate_hz))
            q, _ = s.process_batch(rec.stamps_ns[keep] + 10**18, rec.acc[keep], gyr[keep], mag)
            res[f"{p.name[:2]}_{cond}"] = q
            print(p.name[:2], cond, file=sys.stderr)
    np.savez(out, **res)  # type: ignore[arg-type]


def diff(a_path: str, b_path: str) -> None:
    a, b = np.load(a_path), np.load(b_path)
    worst = 0.0
    for k in a.files:
        x, y = a[k], b[k]
        same = bool((np.isfinite(x) == np.isfinite(y)).all())
        d = float(np.nanmax(np.abs(x - y)))
        worst = max(worst, d)
        print(f"{k}: {len(x)} samples, max |Δq| {d:.3g}, same accepted samples: {same}")
    print(f"max |Δq| over all: {worst:.3g}")


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "run":
        run(sys.argv[2])
    elif len(sys.argv) == 4 and sys.argv[1] == "diff":
        diff(sys.argv[2], sys.argv[3])
    else:
        sys.exit(__doc__)
