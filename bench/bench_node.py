#!/usr/bin/env python3
"""riann_node throughput and latency over real DDS, with references measured in the same run.

    .venv/bin/python bench/bench_node.py [--rates 200,1000,2000,4000] [--duration 60] [--node riann_node] [--pin]

``--node`` takes a comma-separated list (e.g. ``riann_node,madgwick_node,mahony_node,vqf_node``). ``--pin`` runs each
node on CPU 0 alone (``taskset``, ONNX Runtime and BLAS with one thread) and this harness on the other CPUs; the
``cpu_share`` column is the node's CPU time (user + system, from /proc) per second of IMU stream, as a percentage of
one core: what the node costs a robot's computer at that rate.

For each input rate it starts the node (the installed executable), publishes synthetic IMU samples
on a fixed schedule (header stamps = the schedule, like a real IMU), collects ``imu/attitude`` and
reports: messages in / out, drops, late (end-to-end latency > 1 ms), end-to-end latency p50/p99
(publication in this process → arrival of the output here: two DDS hops plus this process's own
callback), and the node's own processing time p99 from its /diagnostics (callback entry →
publication). References in the same run: one ONNX Runtime GRU step, a whole sequence per sample,
and an rclpy echo node's end-to-end latency (subscribe + republish, no estimation).

DDS stays on this machine: ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, ROS_DOMAIN_ID=57 by default.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("ROS_DOMAIN_ID", "57")

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import QuaternionStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu

from riann_ros import defaults, stamps

BIN = Path(sys.executable).parent
ECHO = """
import rclpy, sys
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu
from geometry_msgs.msg import QuaternionStamped
rclpy.init()
n = rclpy.create_node("echo_node")
pub = n.create_publisher(QuaternionStamped, "imu/attitude", QoSProfile(depth=100))
out = QuaternionStamped()
def cb(m):
    out.header = m.header
    pub.publish(out)
n.create_subscription(Imu, "imu/data_raw", cb, QoSProfile(depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT))
try:
    rclpy.spin(n)
except KeyboardInterrupt:
    pass
"""


def onnx_reference() -> tuple[float, float]:
    """µs per single ONNX Runtime step, µs per sample over a whole sequence (same session)."""
    from riann_ros.estimators.riann import open_model

    _, s = open_model()
    shape = (2, 1, 1, 200)
    h = np.zeros(shape, np.float32)
    x1 = np.array([[[0.1, 0.2, 9.8, 0.01, 0.02, 0.03, 0.005]]], np.float32)
    for _ in range(50):
        s.run(None, {"input": x1, "h0": h})
    n = 2000
    t0 = time.perf_counter()
    for _ in range(n):
        _, h = s.run(None, {"input": x1, "h0": h})
    step = (time.perf_counter() - t0) / n * 1e6
    xs = np.repeat(x1, 20000, axis=1)
    t0 = time.perf_counter()
    s.run(None, {"input": xs, "h0": np.zeros(shape, np.float32)})
    seq = (time.perf_counter() - t0) / 20000 * 1e6
    return step, seq


class Harness:
    def __init__(self) -> None:
        rclpy.init()
        self.node = rclpy.create_node("bench_node_harness")
        self.pub = self.node.create_publisher(Imu, "imu/data_raw", QoSProfile(depth=1000))
        self.arrivals: dict[int, int] = {}
        self.proc_p99: list[float] = []
        self.sent: dict[int, int] = {}
        self.on_connected: Callable[[int], None] | None = None  # called with the node's pid once it is connected
        self.node.create_subscription(QuaternionStamped, "imu/attitude", self._on_out,
                                      QoSProfile(depth=10000, reliability=ReliabilityPolicy.RELIABLE))
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diag, 10)
        self.ex = SingleThreadedExecutor()
        self.ex.add_node(self.node)
        self.spinner = threading.Thread(target=self.ex.spin, daemon=True)
        self.spinner.start()

    def _on_out(self, m: QuaternionStamped) -> None:
        self.arrivals[stamps.to_ns(m.header.stamp)] = time.perf_counter_ns()

    def _on_diag(self, m: DiagnosticArray) -> None:
        for s in m.status:
            for kv in s.values:
                if kv.key == "processing time p99 (us)" and kv.value != "nan":
                    self.proc_p99.append(float(kv.value))

    def run(self, cmd: list[str], rate: float, duration: float) -> dict[str, float]:
        self.arrivals.clear()
        self.proc_p99.clear()
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            end = time.monotonic() + 30
            while self.pub.get_subscription_count() == 0 or self.node.count_publishers("/imu/attitude") == 0:
                if time.monotonic() > end:
                    raise RuntimeError("node did not connect")
                time.sleep(0.05)
            time.sleep(1.0)  # let discovery settle both ways
            if self.on_connected is not None:
                self.on_connected(proc.pid)
            cpu0 = _cpu_seconds(proc.pid)
            n = int(rate * duration)
            rng = np.random.default_rng(0)
            acc = np.array([0.3, -0.2, 9.8]) + rng.normal(0, 0.3, (n, 3))
            gyr = rng.normal(0, 0.5, (n, 3))
            sent: dict[int, int] = {}
            self.sent = sent  # stamp → perf_counter_ns at publication (CLOCK_MONOTONIC: comparable across processes)
            msg = Imu()
            msg.header.frame_id = defaults.IMU_FRAME
            t0_ns = 1_700_000_000_000_000_000
            period = 1.0 / rate
            start = time.perf_counter()
            behind = 0
            for i in range(n):
                target = start + i * period
                while True:
                    now = time.perf_counter()
                    if now >= target:
                        break
                    if target - now > 0.0005:
                        time.sleep(target - now - 0.0003)
                if now - target > 0.002:
                    behind += 1
                stamp = t0_ns + round(i * period * 1e9)
                stamps.set_ns(msg.header.stamp, stamp)
                a, g = acc[i], gyr[i]
                la, av = msg.linear_acceleration, msg.angular_velocity
                la.x, la.y, la.z = float(a[0]), float(a[1]), float(a[2])
                av.x, av.y, av.z = float(g[0]), float(g[1]), float(g[2])
                sent[stamp] = time.perf_counter_ns()
                self.pub.publish(msg)
            achieved = n / (time.perf_counter() - start)
            time.sleep(1.5)
            cpu = _cpu_seconds(proc.pid) - cpu0
        finally:
            proc.send_signal(2)
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:  # a node that does not end on Ctrl-C
                print(f"{cmd[0]} did not stop within 10 s of SIGINT: killed", file=sys.stderr)
                proc.kill()
                proc.wait(10)
        lat = np.array([(self.arrivals[s] - t) * 1e-3 for s, t in sent.items() if s in self.arrivals])
        return {
            "rate": rate,
            "achieved_rate": achieved,
            "sent": float(n),
            "received": float(len(lat)),
            "dropped": float(n - len(lat)),
            "late_over_1ms": float((lat > 1000).sum()) if len(lat) else float("nan"),
            "e2e_p50_us": float(np.percentile(lat, 50)) if len(lat) else float("nan"),
            "e2e_p99_us": float(np.percentile(lat, 99)) if len(lat) else float("nan"),
            "node_proc_p99_us": max(self.proc_p99) if self.proc_p99 else float("nan"),
            "publisher_behind": float(behind),
            "cpu_share": 100.0 * cpu / (n / rate),
        }


def _cpu_seconds(pid: int) -> float:
    """User + system CPU time (s) of a process so far (its threads included)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _remap(node: str) -> list[str]:
    """The classical filters publish imu/<name>/attitude (docs/node.md): remapped to the harness's imu/attitude."""
    name = node.removesuffix("_node")
    return [] if name == "riann" else ["-r", f"imu/{name}/attitude:=imu/attitude"]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rates", default="200,1000,2000,4000")
    ap.add_argument("--duration", type=float, default=60.0, help="seconds per rate")
    ap.add_argument("--node", default="riann_node")
    ap.add_argument("--no-echo", action="store_true", help="skip the echo-node reference")
    ap.add_argument("--pin", action="store_true", help="node alone on CPU 0 with one thread, this harness elsewhere")
    args = ap.parse_args()
    pin: list[str] = []
    if args.pin:
        cpus = sorted(os.sched_getaffinity(0))
        if len(cpus) < 2:
            raise SystemExit("--pin needs two CPUs")
        os.sched_setaffinity(0, set(cpus[1:]))
        pin = ["taskset", "-c", str(cpus[0])]
        for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
            os.environ[var] = "1"
    step, seq = onnx_reference()
    print(f"ONNX Runtime: single step {step:.1f} us, whole sequence {seq:.1f} us/sample")
    h = Harness()
    cols = ["rate", "achieved_rate", "sent", "received", "dropped", "late_over_1ms", "e2e_p50_us", "e2e_p99_us",
            "node_proc_p99_us", "publisher_behind", "cpu_share"]
    print("| what | " + " | ".join(cols) + " |")
    print("|---" * (len(cols) + 1) + "|")
    for rate in [float(r) for r in args.rates.split(",")]:
        runs = [(node, [*pin, str(BIN / node), "--ros-args", "-p", f"nominal_rate:={rate}", *_remap(node)])
                for node in args.node.split(",")]
        if not args.no_echo:
            runs.append(("echo (reference)", [*pin, sys.executable, "-c", ECHO]))
        for label, cmd in runs:
            r = h.run(cmd, rate, args.duration)
            print(f"| {label} | " + " | ".join(f"{r[c]:.0f}" for c in cols) + " |", flush=True)
    h.ex.shutdown()
    h.spinner.join(timeout=5.0)  # the spin thread must end before the process does (else: std::terminate)
    h.node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
