"""Per-sample cost of the online magnetometer calibration against RIANN's per-sample ``update()`` (9D), same run.

Usage::

    .venv/bin/python bench/bench_magcal.py [--rounds 3] [--samples 6000]

A 200 Hz stream of rich rotation (the synthetic generator) with a distorted field: per sample the calibration's
``update()`` (gyro increment into the window, the reading calibrated; the window's linear algebra when one closes)
and ``heading_sd_rad()``, in plain floats as the heading stage would call them; the reference is RIANN's
``update()`` with the field on the same samples (ensemble 4). Each figure is the best of
``--rounds`` runs in one process; the ratio is what the calibration would add to RIANN's per-sample cost.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from riann_ros import quaternion as quat
from riann_ros.datasets.synthetic import generate
from riann_ros.estimators import create
from riann_ros.magcal.online import OnlineMagCalibrator
from riann_ros.magcal.records import UT
from riann_ros.magcal.synthetic import distort
from riann_ros.rotations import rotate


def calibration_us(rec, raw, model: str) -> tuple[float, int]:
    inc = [tuple(v) for v in quat.from_rotvec(rec.gyr * rec.dt[:, None]).tolist()]
    dts, mags, qs = rec.dt.tolist(), [tuple(v) for v in raw.tolist()], [tuple(v) for v in rec.quat_ref.tolist()]
    cal = OnlineMagCalibrator(soft_iron_model=model)  # type: ignore[arg-type]
    t0 = time.perf_counter()
    for i in range(len(dts)):
        q = qs[i]
        u = cal.update(inc[i], dts[i], mags[i], 0.01, q)
        if u is not None:
            cal.heading_sd_rad(q, rotate(q, u))
    return (time.perf_counter() - t0) / len(dts) * 1e6, cal.windows


def riann_us(rec, raw) -> float:
    est = create("riann", ensemble=4)
    a, g, d, m = rec.acc.tolist(), rec.gyr.tolist(), rec.dt.tolist(), raw.tolist()
    t0 = time.perf_counter()
    for i in range(len(d)):
        est.update(a[i], g[i], d[i], m[i])
    return (time.perf_counter() - t0) / len(d) * 1e6


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--samples", type=int, default=6000)
    a = ap.parse_args()
    rec = generate(duration=a.samples / 200.0, rate=200, motion="rotation", bias=0.0, seed=3)
    raw = distort(rec.quat_ref, np.array([20.0, 0.0, -10.0]) * UT, noise_t=0.3e-6)
    best: dict[str, float] = {}
    windows = {}
    for _ in range(a.rounds):
        best["riann"] = min(best.get("riann", np.inf), riann_us(rec, raw))
        for model in ("none", "symmetric", "full"):
            us, windows[model] = calibration_us(rec, raw, model)
            best[model] = min(best.get(model, np.inf), us)
    print(f"per-sample cost, µs, best of {a.rounds} × {len(rec)} samples (200 Hz rich rotation)")
    print(f"RIANN update() 9D, ensemble 4: {best['riann']:.1f}")
    for model in ("none", "symmetric", "full"):
        print(f"calibration {model:9s}: {best[model]:.1f} ({100 * best[model] / best['riann']:.1f} % of RIANN; "
              f"{windows[model]} windows)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
