#!/usr/bin/env python3
"""Memory and time of ``riann-bag-eval`` on long synthetic 1 kHz bags.

    .venv/bin/python bench/bench_long_bag.py [--durations 600,1800,3600] [--rate 1000]
        [--estimators madgwick] [--scenarios realistic] [--tmp DIR]

For each duration it writes a synthetic bag with the installed ``riann-bag-convert`` into a temporary
directory (deleted at the end, never in the repository), then runs, each in a child process of its
own whose peak resident memory is read from ``os.wait4`` (``ru_maxrss``) and whose RSS is sampled
from ``/proc/<pid>/status`` every 0.2 s:

* ``riann-bag-convert --format synthetic`` (the bag's generation),
* ``riann-bag-eval <bag> --estimators ... --scenarios ... --no-plots`` (the evaluator as shipped),
* a streaming pass for comparison: ``bagio.iter_imu_chunks`` (100 000 samples per chunk) through
  ``EstimatorStream.process_batch`` per chunk — what bounded-memory evaluation would cost.

Prints one markdown table row per (duration, program): samples, wall time, peak RSS.
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

BIN = Path(sys.executable).parent

STREAM = r"""
import sys, time
import numpy as np
from riann_ros import bagio
from riann_ros.estimators import create
from riann_ros.stream import EstimatorStream, GateConfig
path, names = sys.argv[1], sys.argv[2].split(",")
streams = None
n = 0
for chunk in bagio.iter_imu_chunks(path, chunk=100_000):
    if streams is None:
        streams = [EstimatorStream(create(k), GateConfig(nominal_rate=chunk.rate_hz)) for k in names]
    for s in streams:
        q, ok = s.process_batch(chunk.stamps_ns, chunk.acc, chunk.gyr)
    n += len(chunk)
print(n, "samples streamed")
"""


def run_measured(cmd: list[str], log: Path) -> dict[str, float]:
    """Run cmd as a child; wall time, peak RSS (wait4) and the RSS samples over time."""
    t0 = time.perf_counter()
    with log.open("w") as fh:
        p = subprocess.Popen(cmd, stdout=fh, stderr=subprocess.STDOUT)
    samples: list[tuple[float, int]] = []

    def sample() -> None:
        while True:
            try:
                text = Path(f"/proc/{p.pid}/status").read_text()
            except OSError:
                return
            kb = next((int(ln.split()[1]) for ln in text.splitlines() if ln.startswith("VmRSS:")), None)
            if kb is None:
                return
            samples.append((time.perf_counter() - t0, kb))
            time.sleep(0.2)

    th = threading.Thread(target=sample, daemon=True)
    th.start()
    _, status, ru = os.wait4(p.pid, 0)
    wall = time.perf_counter() - t0
    rc = os.waitstatus_to_exitcode(status)
    p.returncode = rc
    th.join(1)
    return {"rc": rc, "wall_s": wall, "peak_mb": ru.ru_maxrss / 1024, "cpu_s": ru.ru_utime + ru.ru_stime,
            "rss_samples": samples}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--durations", default="600,1800,3600", help="bag lengths in seconds, comma-separated")
    ap.add_argument("--rate", type=float, default=1000.0)
    ap.add_argument("--estimators", default="madgwick", help="for riann-bag-eval and the streaming pass")
    ap.add_argument("--scenarios", default="realistic")
    ap.add_argument("--tmp", type=Path, default=None, help="parent of the temporary directory (default: system)")
    ap.add_argument("--no-stream", action="store_true", help="skip the streaming comparison")
    args = ap.parse_args()
    durations = [float(x) for x in args.durations.split(",") if x.strip()]
    tmp = Path(tempfile.mkdtemp(prefix="riann_long_bag_", dir=args.tmp))
    print(f"# python {platform.python_version()} {platform.machine()}, {os.cpu_count()} CPUs, "
          f"load average before {os.getloadavg()[0]:.2f}; temp dir {tmp} (deleted at the end)")
    print(f"# riann-bag-eval --estimators {args.estimators} --scenarios {args.scenarios} --no-plots -q")
    print("| bag | samples | bag MB | program | wall s | CPU s | peak RSS MB |")
    print("|---|---:|---:|---|---:|---:|---:|")
    ok = True
    try:
        for d in durations:
            bag = tmp / f"syn_{int(d)}s.mcap"
            n = int(d * args.rate) + 1
            label = f"{d:g} s @ {args.rate:g} Hz"
            runs = [
                ("riann-bag-convert (generate + write)",
                 [str(BIN / "riann-bag-convert"), "--format", "synthetic", "--rate", f"{args.rate:g}",
                  "--duration", f"{d:g}", "--seed", "1", "-o", str(bag), "-q"]),
                ("riann-bag-eval",
                 [str(BIN / "riann-bag-eval"), str(bag), "--estimators", args.estimators, "--scenarios",
                  args.scenarios, "--no-plots", "-q", "--out", str(tmp / f"eval_{int(d)}")]),
            ]
            if not args.no_stream:
                runs.append((f"streaming pass ({args.estimators})",
                             [sys.executable, "-c", STREAM, str(bag), args.estimators]))
            for name, cmd in runs:
                r = run_measured(cmd, tmp / "log.txt")
                size = bag.stat().st_size / 1e6 if bag.exists() else float("nan")
                if r["rc"] != 0:
                    ok = False
                    print(f"<!-- {name} failed ({r['rc']}): {(tmp / 'log.txt').read_text()[-2000:]} -->")
                print(f"| {label} | {n:,} | {size:.0f} | {name} | {r['wall_s']:.1f} | {r['cpu_s']:.1f} | "
                      f"{r['peak_mb']:.0f} |", flush=True)
            bag.unlink(missing_ok=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print(f"# load average after {os.getloadavg()[0]:.2f}")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
