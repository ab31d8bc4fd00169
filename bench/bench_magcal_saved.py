"""A saved magnetometer calibration used at the next start: per BROAD trial, RIANN calibrates online with a hard-iron
offset injected (first run), its final calibration is the prior of a second run on the same readings (as
``mag_calibration_file`` would load it), and both are compared with RIANN on the recorded (calibrated) field.

Usage::

    .venv/bin/python bench/bench_magcal_saved.py [--offset 20,0,-10] [--jobs 2] [--write]

Heading RMSE (°) over BROAD's movement mask, the whole trial, as ``riann-bag-eval`` scores it (the trials' own
mask, as recorded). ``--write`` stores the figures in docs/results/magcal_saved.json (the table
``<!-- results:magcal-saved -->`` of BENCHMARKS.md, bench/results_tables.py).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def heading_rmse(rec, q) -> float:
    from riann_ros import quaternion as quat

    ok = (np.asarray(rec.score_mask, dtype=bool) & np.isfinite(q).all(axis=1)
          & np.isfinite(rec.quat_ref).all(axis=1))
    return float(np.sqrt(np.mean(np.degrees(quat.heading_error(rec.quat_ref[ok], q[ok])) ** 2)))


def trial(args: tuple[str, tuple[float, float, float]]) -> dict:
    os.environ["OMP_NUM_THREADS"] = "1"
    from riann_ros.datasets import read_any
    from riann_ros.estimators import create
    from riann_ros.gate import GateConfig
    from riann_ros.magcal.input import MagConfig
    from riann_ros.magcal.records import MagCalPrior
    from riann_ros.stream import EstimatorStream

    path, offset = args
    rec = read_any(path)
    raw = rec.mag + np.asarray(offset) * 1e-6
    est = create("riann")

    streams: list[EstimatorStream] = []

    def run(mag, prior=None):
        est.reset()
        s = EstimatorStream(est, GateConfig(), MagConfig(), prior)
        streams.append(s)
        return s.process_batch(rec.stamps_ns, rec.acc, rec.gyr, mag)[0]

    first = heading_rmse(rec, run(raw))
    cal = streams[0].mag_calibration()
    assert cal is not None
    second = heading_rmse(rec, run(raw, MagCalPrior.from_calibration(cal)))
    recorded = heading_rmse(rec, run(rec.mag))
    return {"trial": Path(path).name[:2], "first": first, "second": second, "recorded": recorded,
            "hard_iron_uT": [round(v * 1e6, 3) for v in cal.hard_iron_t], "state": cal.state}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--offset", default="20,0,-10", help="µT, the hard iron injected (sensor frame)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--write", action="store_true", help="store the figures in docs/results/magcal_saved.json")
    args = ap.parse_args()
    from riann_ros.datasets.broad import broad_files, find_broad_dir

    where = find_broad_dir()
    if where is None:
        print("BROAD not found (RIANN_BROAD_DIR)", file=sys.stderr)
        return 1
    offset = tuple(float(v) for v in args.offset.split(","))
    files = [str(p) for p in broad_files(where)]
    with multiprocessing.get_context("spawn").Pool(args.jobs) as pool:
        rows = sorted(pool.map(trial, [(f, offset) for f in files]), key=lambda r: r["trial"])
    for r in rows:
        print(f"{r['trial']}: first {r['first']:.2f}  second {r['second']:.2f}  recorded {r['recorded']:.2f}  "
              f"difference {r['second'] - r['recorded']:+.2f}  h {r['hard_iron_uT']} ({r['state']})")
    if args.write:
        cmd = f".venv/bin/python bench/bench_magcal_saved.py --offset {args.offset} --jobs {args.jobs} --write"
        rounded = [{k: round(v, 4) if isinstance(v, float) else v for k, v in r.items()} for r in rows]
        (ROOT / "docs" / "results" / "magcal_saved.json").write_text(
            json.dumps({"command": cmd, "rows": rounded}, indent=1, ensure_ascii=False) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
