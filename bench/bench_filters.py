#!/usr/bin/env python3
"""Speed of the project's Madgwick, Mahony and VQF estimators against the ``ahrs`` package.

Runs every filter in batch mode over the same sequence in the same process (a BROAD trial, or a
synthetic 100 Hz sequence when BROAD is absent), best of ``--repeat`` runs, and prints samples/s and
the ratio ours / ahrs. Also times the per-sample ``update`` path (what a node calls per message).

    .venv/bin/python bench/bench_filters.py [--broad-dir DIR] [--trial 15] [--repeat 3]
"""

from __future__ import annotations

import argparse
import platform
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from riann_ros import quaternion as quat
from riann_ros.estimators import create


def load(broad_dir: str | None, trial: str) -> tuple[str, np.ndarray, np.ndarray, float]:
    from riann_ros.datasets.broad import broad_files, find_broad_dir, read_broad

    d = Path(broad_dir) if broad_dir else find_broad_dir()
    if d is not None and d.is_dir():
        files = broad_files(d)
        pick = [f for f in files if f.name.startswith(f"{trial}_")] or files
        if pick:
            rec = read_broad(pick[0])
            return f"BROAD {pick[0].name}", rec.acc, rec.gyr, float(rec.meta["sampling_rate"])
    # synthetic fallback: 50,000 samples of smooth rotation at 100 Hz
    n, rate = 50_000, 100.0
    t = np.arange(n) / rate
    gyr = np.column_stack([0.8 * np.sin(0.7 * t), 0.6 * np.sin(1.1 * t + 1.0), 0.5 * np.cos(0.4 * t)])
    q = np.empty((n, 4))
    q[0] = quat.IDENTITY
    for i in range(1, n):
        q[i] = quat.normalize(quat.multiply(q[i - 1], quat.from_rotvec(gyr[i] / rate)))
    acc = quat.rotate(quat.conjugate(q), np.array([0.0, 0.0, 9.81]))
    return "synthetic (BROAD not found)", acc, gyr, rate


def best_time(fn: Callable[[], object], repeat: int) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--broad-dir", help="BROAD folder (default: $RIANN_BROAD_DIR or ../shared/datasets/broad)")
    ap.add_argument("--trial", default="15", help="BROAD trial number prefix (default 15)")
    ap.add_argument("--repeat", type=int, default=3, help="runs per filter, best taken (default 3)")
    ap.add_argument("--stream-samples", type=int, default=5000, help="samples for the per-sample update timing")
    args = ap.parse_args()

    from importlib.metadata import version

    import ahrs

    label, acc, gyr, rate = load(args.broad_dir, args.trial)
    n = len(acc)
    dt = np.full(n, 1.0 / rate)
    q0 = quat.from_accelerometer(acc[0])
    print(f"machine: {platform.node()} | {cpu_model()} | {platform.machine()} | Python {platform.python_version()}")
    print(f"numpy {np.__version__}, AHRS {version('AHRS')}, vqf {version('vqf')}")
    print(f"data: {label}, {n} samples at {rate:.1f} Hz; best of {args.repeat} runs")
    print()

    def ours(name: str, **params: object) -> Callable[[], object]:
        return lambda: create(name, **params).update_batch(acc, gyr, dt)

    pairs = [
        (
            "madgwick (beta=0.033)",
            ours("madgwick", beta=0.033),
            lambda: ahrs.filters.Madgwick(gyr=gyr, acc=acc, frequency=rate, q0=q0, gain=0.033),
        ),
        (
            "mahony (kp=1, ki=0.3)",
            ours("mahony", kp=1.0, ki=0.3),
            lambda: ahrs.filters.Mahony(gyr=gyr, acc=acc, frequency=rate, q0=q0, k_P=1.0, k_I=0.3),
        ),
        ("vqf (6D, defaults)", ours("vqf"), None),
    ]
    print(f"{'filter':24s} {'ours batch [samples/s]':>24s} {'ahrs batch [samples/s]':>24s} {'ours / ahrs':>12s}")
    for title, mine, ref in pairs:
        t_ours = best_time(mine, args.repeat)
        if ref is not None:
            t_ref = best_time(ref, args.repeat)
            print(f"{title:24s} {n / t_ours:24,.0f} {n / t_ref:24,.0f} {t_ref / t_ours:11.1f}x")
        else:
            print(f"{title:24s} {n / t_ours:24,.0f} {'-':>24s} {'-':>12s}")

    m = min(args.stream_samples, n)
    print()
    print(f"per-sample update() over the first {m} samples (one call per sample, as a node does):")
    for name in ("madgwick", "mahony", "vqf"):

        def stream(name: str = name) -> None:
            est = create(name)
            for i in range(m):
                est.update(acc[i], gyr[i], float(dt[i]))

        t = best_time(stream, args.repeat)
        print(f"  {name:10s} {m / t:10,.0f} samples/s ({1e6 * t / m:.1f} µs per sample)")


if __name__ == "__main__":
    main()
