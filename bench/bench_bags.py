#!/usr/bin/env python3
"""Bag I/O speed and memory: write/read a synthetic 1 kHz recording in every storage, chunked read.

    .venv/bin/python bench/bench_bags.py [--rate 1000] [--duration 600] [--chunk 100000]

Prints samples/s for ``write_recording`` and ``read_recording`` per storage/compression, bag size, and
the peak Python heap (tracemalloc) of ``read_recording`` vs ``iter_imu_chunks``.
"""

from __future__ import annotations

import argparse
import platform
import shutil
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

from riann_ros import bagio
from riann_ros.datasets.synthetic import generate


def size(p: Path) -> int:
    return p.stat().st_size if p.is_file() else sum(f.stat().st_size for f in p.rglob("*") if f.is_file())


def peak(fn) -> tuple[float, float]:
    tracemalloc.start()
    t = time.perf_counter()
    fn()
    dt = time.perf_counter() - t
    _, pk = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return dt, pk / 1e6


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--rate", type=float, default=1000.0)
    ap.add_argument("--duration", type=float, default=600.0)
    ap.add_argument("--chunk", type=int, default=100_000)
    args = ap.parse_args()
    rec = generate(rate=args.rate, duration=args.duration, seed=1)
    n = len(rec)
    print(
        f"# {n} samples ({args.rate:g} Hz × {args.duration:g} s), python {platform.python_version()}, "
        f"{platform.machine()}"
    )
    print("| storage | compression | write samples/s | read samples/s | size MB |")
    print("|---|---|---|---|---|")
    tmp = Path(tempfile.mkdtemp())
    try:
        for name, storage, comp in (
            ("a.mcap", "mcap", None),
            ("b.mcap", "mcap", "zstd"),
            ("c", "sqlite3", None),
            ("d", "sqlite3", "zstd"),
        ):
            p = tmp / name
            t = time.perf_counter()
            bagio.write_recording(p, rec, storage=storage, compression=comp)
            tw = time.perf_counter() - t
            t = time.perf_counter()
            bagio.read_recording(p)
            tr = time.perf_counter() - t
            print(f"| {storage} | {comp or 'none'} | {n / tw:,.0f} | {n / tr:,.0f} | {size(p) / 1e6:.1f} |")
        p = tmp / "a.mcap"
        t_full, m_full = peak(lambda: bagio.read_recording(p))

        def chunked() -> None:
            for _ in bagio.iter_imu_chunks(p, chunk=args.chunk):
                pass

        t_chunk, m_chunk = peak(chunked)
        print(
            f"\npeak Python heap reading {p.name}: read_recording {m_full:.0f} MB ({t_full:.1f} s), "
            f"iter_imu_chunks(chunk={args.chunk}) {m_chunk:.0f} MB ({t_chunk:.1f} s)"
        )
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
