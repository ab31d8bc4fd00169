"""How far a magnetometer's hard iron moves between runs of one sensor: the figure behind
:data:`riann_ros.magcal.records.RUN_TO_RUN_HARD_IRON_SD_UT`, the doubt a saved calibration gets at the next start.

Usage::

    .venv/bin/python bench/mag_run_to_run.py [--max-sd 1.0]

Each BROAD trial (``$RIANN_BROAD_DIR`` or ``../shared/datasets/broad``; one sensor, recorded in one lab) gets the
offline fit of ``riann-mag-calibrate`` (:func:`riann_ros.magcal.bag_fit.calibrate_recording`, gyro-aided, 10 ms
latency). Trials whose fit leaves a hard-iron axis above ``--max-sd`` µT (motion that does not observe it: BROAD's
translations and the barely turning trials) are left out. Prints each fit, then per axis the RMS of the difference
between every two kept trials (what a file saved on one run is off by on another), pooled over the axes, and the
fits' own σ. Takes about 5 minutes on two cores.
"""

from __future__ import annotations

import argparse
import itertools
import sys

import numpy as np

from riann_ros.datasets import read_any
from riann_ros.datasets.broad import broad_files, find_broad_dir
from riann_ros.estimators.motion import gyro_motion
from riann_ros.magcal.bag_fit import calibrate_recording


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--max-sd", type=float, default=1.0, help="µT; leave out trials whose fit is less certain")
    args = ap.parse_args(argv)
    folder = find_broad_dir()
    if folder is None:
        print("BROAD not found: set RIANN_BROAD_DIR", file=sys.stderr)
        return 2
    kept: list[np.ndarray] = []
    sds: list[np.ndarray] = []
    for path in broad_files(folder):
        cal = calibrate_recording(read_any(str(path)), gyro_motion, delay_s=0.01).fit.calibration
        h, sd = np.array(cal.hard_iron_t) * 1e6, np.array(cal.hard_iron_sd_t) * 1e6
        use = bool(sd.max() <= args.max_sd)
        print(f"{path.name[:2]}  hard iron {np.round(h, 2)} µT ± {np.round(sd, 2)}  {'kept' if use else 'left out'}")
        if use:
            kept.append(h)
            sds.append(sd)
    if len(kept) < 2:
        print("fewer than two trials observe the hard iron", file=sys.stderr)
        return 1
    diffs = np.array([a - b for a, b in itertools.combinations(kept, 2)])
    per_axis = np.sqrt((diffs ** 2).mean(axis=0))
    print(f"{len(kept)} trials, {len(diffs)} pairs: RMS difference per axis {np.round(per_axis, 2)} µT, "
          f"pooled {np.sqrt((diffs ** 2).mean()):.2f} µT; the fits' own σ {np.mean(sds):.2f} µT; "
          f"median |difference| {np.median(np.linalg.norm(diffs, axis=1)):.2f} µT, "
          f"largest {np.linalg.norm(diffs, axis=1).max():.2f} µT")
    return 0


if __name__ == "__main__":
    sys.exit(main())
