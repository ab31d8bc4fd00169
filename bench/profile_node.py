#!/usr/bin/env python3
"""Where an estimator node's latency and CPU go under load: timed callbacks, GC pauses and a sampling profile.

    .venv/bin/python bench/profile_node.py [--rate 1000] [--duration 30] [--node riann] [--executor single]
                                           [--py-spy SECONDS] [--check-events 8000]

Three measurements, each with the bench_node.py harness (synthetic IMU published on a fixed schedule from this
process, the node's ``imu/attitude`` collected here; DDS on this machine only):

1. **Timed run** (always): the node class runs in a child process of this script, unchanged, under a subclass that
   times its callbacks (the ``imu/data_raw`` callback, and inside it the input gate, the estimator's planning,
   network and composition, publishing, logging; the diagnostics timer) and Python's garbage collector
   (``gc.callbacks``). Publication, callback entry and exit and arrival share one clock (CLOCK_MONOTONIC), so
   each message's end-to-end latency splits into *inbound* (DDS, the executor's wait and dispatch, queueing behind
   earlier callbacks), *callback* and what follows the callback's exit (DDS, the harness's callback). The table
   gives the split for all messages and for the slowest 1 %, and what ran while those waited. The timing adds
   about 1 µs per timed call.
2. **Sampling profile** (``--py-spy SECONDS``): the installed node executable, unchanged, profiled by py-spy
   (``pip install py-spy``; not a project dependency) at 1 kHz without pausing it (``--nonblocking``, which
   cannot read native frames: garbage collection is not seen here, the timed run counts it), busy threads only
   (where the CPU goes; the timed run gives the wall time), its stacks sorted into the same categories.
3. **EventsExecutor check** (``--check-events N``): an echo node spun by rclpy's experimental EventsExecutor and by
   the SingleThreadedExecutor gets N messages at ``--rate``; how many come back.
4. **Executor cost** (``--executor-cost N``): in this process, N messages queued for a node with a trivial callback,
   then taken by ``SingleThreadedExecutor.spin_once`` (nodes with more or fewer entities) or directly
   (``subscription.handle.take_message``): µs per message.

The child's records are written to a temporary file and read back here.
"""

from __future__ import annotations

import argparse
import gc
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path
from typing import Any

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("ROS_DOMAIN_ID", "58")

import numpy as np
from bench_node import BIN, Harness

NODES = {"riann": "riann_ros.nodes.riann_node:RiannNode", "madgwick": "riann_ros.nodes.madgwick_node:MadgwickNode",
         "mahony": "riann_ros.nodes.mahony_node:MahonyNode", "vqf": "riann_ros.nodes.vqf_node:VqfNode"}


# -- the child: the node under timing ---------------------------------------------------------------------
def _timed(fn: Any, rec: dict[str, int], key: str) -> Any:
    def wrapper(*a: Any, **k: Any) -> Any:
        t0 = time.perf_counter_ns()
        try:
            return fn(*a, **k)
        finally:
            rec[key] += time.perf_counter_ns() - t0

    return wrapper


def child(out: str, node_spec: str, executor: str, freeze: bool) -> int:
    import importlib

    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

    module, cls_name = node_spec.split(":")
    base = getattr(importlib.import_module(module), cls_name)
    rows: list[tuple[int, ...]] = []
    diag: list[tuple[int, int]] = []
    gcs: list[tuple[int, int, int]] = []
    rec: dict[str, int] = dict.fromkeys(("gate", "process", "plan", "network", "compose", "publish", "logging"), 0)
    gc_start = [0]

    def on_gc(phase: str, info: dict[str, int]) -> None:
        if phase == "start":
            gc_start[0] = time.perf_counter_ns()
        else:
            gcs.append((gc_start[0], time.perf_counter_ns(), info["generation"]))

    from riann_ros.estimators.riann import s1_timeline, s2_grid, s4_network, s5_carry, s6_handover, s7_heading

    for cls, key in ((s1_timeline.Timeline, "plan"), (s2_grid.Grid, "plan"), (s4_network.Network, "network"),
                     (s5_carry.Carry, "compose"), (s6_handover.Handover, "compose"), (s7_heading.Heading, "compose")):
        cls.run = _timed(cls.run, rec, key)  # type: ignore[method-assign]

    class Timed(base):  # type: ignore[misc, valid-type]
        def __init__(self) -> None:
            super().__init__()
            s = self.stream
            s.gate.check = _timed(s.gate.check, rec, "gate")
            s.process = _timed(s.process, rec, "process")
            self.outputs.publish = _timed(self.outputs.publish, rec, "publish")
            inner = self.diag.publish

            def diag_publish() -> None:
                t0 = time.perf_counter_ns()
                inner()
                diag.append((t0, time.perf_counter_ns()))

            self.diag.publish = diag_publish  # the timer holds the bound method: re-create it
            for timer in list(self.timers):
                if getattr(timer, "callback", None) == inner:
                    timer.callback = diag_publish
            for name in ("_log_gate_result", "_log_mag_state", "_warn_throttled"):
                setattr(self, name, _timed(getattr(self, name), rec, "logging"))

        def _on_imu(self, msg: Any) -> None:
            for k in rec:
                rec[k] = 0
            t0 = time.perf_counter_ns()
            super()._on_imu(msg)
            t1 = time.perf_counter_ns()
            st = msg.header.stamp
            rows.append((st.sec * 1_000_000_000 + st.nanosec, t0, t1, *rec.values()))

    rclpy.init()
    node = Timed()
    if freeze:  # what start-up allocated (rclpy, numpy, ONNX Runtime, the node) leaves the collected generations
        gc.collect()
        gc.freeze()
    if executor == "events":
        from rclpy.experimental import EventsExecutor

        ex = EventsExecutor()
    else:
        ex = SingleThreadedExecutor()
    ex.add_node(node)
    gc.callbacks.append(on_gc)
    try:
        ex.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        gc.callbacks.remove(on_gc)
        np.savez(out, rows=np.array(rows, dtype=np.int64).reshape(-1, 3 + len(rec)),
                 diag=np.array(diag, dtype=np.int64).reshape(-1, 2), gc=np.array(gcs, dtype=np.int64).reshape(-1, 3))
        node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0


# -- the harness side -----------------------------------------------------------------------------------------
def _overlap(a0: np.ndarray, a1: np.ndarray, spans: np.ndarray) -> np.ndarray:
    """Per interval [a0, a1): the time (ns) spans (k, 2) cover inside it."""
    if len(spans) == 0:
        return np.zeros(len(a0))
    lo = np.maximum(a0[:, None], spans[None, :, 0])
    hi = np.minimum(a1[:, None], spans[None, :, 1])
    return np.clip(hi - lo, 0, None).sum(axis=1)


def timed_run(h: Harness, args: argparse.Namespace) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        out = str(Path(tmp) / "records.npz")
        cmd = [sys.executable, __file__, "--child", out, "--node", args.node, "--executor", args.executor,
               *(["--gc-freeze"] if args.gc_freeze else []),
               "--ros-args", "-p", f"nominal_rate:={args.rate}"]
        r = h.run(cmd, args.rate, args.duration)
        d = np.load(out)
        rows, diag, gcs = d["rows"], d["diag"], d["gc"]
    print(f"\n## timed run: {args.node}_node, {args.rate:.0f} Hz, {args.duration:.0f} s, executor {args.executor}"
          + (", gc.freeze()" if args.gc_freeze else ""))
    print(f"sent {r['sent']:.0f}, received {r['received']:.0f}, dropped {r['dropped']:.0f}, e2e p50 "
          f"{r['e2e_p50_us']:.0f} µs, p99 {r['e2e_p99_us']:.0f} µs, publisher behind {r['publisher_behind']:.0f}")
    report(rows, diag, gcs, h.sent, h.arrivals, args.duration)


def report(rows: np.ndarray, diag: np.ndarray, gcs: np.ndarray, sent: dict[int, int], arrivals: dict[int, int],
           duration: float) -> None:
    stamp, t_in, t_out = rows[:, 0], rows[:, 1], rows[:, 2]
    gate, process, plan, net, comp, pub, log = (rows[:, 3 + k] for k in range(7))
    keep = np.array([s in sent and s in arrivals for s in stamp.tolist()])
    stamp, t_in, t_out = stamp[keep], t_in[keep], t_out[keep]
    gate, process, plan, net, comp, pub, log = (a[keep] for a in (gate, process, plan, net, comp, pub, log))
    t_sent = np.array([sent[s] for s in stamp.tolist()])
    t_arr = np.array([arrivals[s] for s in stamp.tolist()])
    e2e = (t_arr - t_sent) * 1e-3
    cb = (t_out - t_in) * 1e-3
    parts = {
        "inbound (DDS, executor, queue)": (t_in - t_sent) * 1e-3,
        "callback": cb,
        "  input gate": gate * 1e-3,
        "  estimator: planning": plan * 1e-3,
        "  estimator: network": net * 1e-3,
        "  estimator: composition": comp * 1e-3,
        "  estimator: other": (process - gate - plan - net - comp) * 1e-3,
        "  publish": pub * 1e-3,
        "  logging": log * 1e-3,
        "  callback other (message unpacking, timing)": (cb * 1e3 - process - pub - log) * 1e-3,
        "after the callback (arrival here − callback exit; < 0: arrived before the callback returned)":
            (t_arr - t_out) * 1e-3,
    }
    slow = e2e >= np.percentile(e2e, 99)
    t0 = t_sent[slow]
    t1 = t_in[slow]
    waited_gc = _overlap(t0, t1, gcs[:, :2]) * 1e-3
    waited_diag = _overlap(t0, t1, diag) * 1e-3
    spans = np.column_stack([t_in, t_out])
    waited_cb = _overlap(t0, t1, spans) * 1e-3
    print(f"\n{len(e2e)} messages; e2e p50 {np.percentile(e2e, 50):.0f} µs, p99 {np.percentile(e2e, 99):.0f} µs")
    print("| part | mean µs | p50 µs | p99 µs | mean over the slowest 1 % µs |")
    print("|---|---:|---:|---:|---:|")
    for k, v in parts.items():
        p50, p99 = np.percentile(v, [50, 99])
        print(f"| {k} | {v.mean():.1f} | {p50:.1f} | {p99:.1f} | {v[slow].mean():.1f} |")
    print(f"| e2e | {e2e.mean():.1f} | {np.percentile(e2e, 50):.1f} | {np.percentile(e2e, 99):.1f} | "
          f"{e2e[slow].mean():.1f} |")
    wait = (t1 - t0) * 1e-3
    rest = wait - waited_cb - waited_gc - waited_diag
    print(f"\nthe slowest 1 % ({slow.sum()}) waited {wait.mean():.0f} µs on average before their callback; during that "
          f"wait: earlier IMU callbacks ran {waited_cb.mean():.0f} µs, garbage collection {waited_gc.mean():.0f} µs, "
          f"the diagnostics timer {waited_diag.mean():.0f} µs; the rest ({rest.mean():.0f} µs) is DDS, the executor "
          "and the harness (not in a callback of the node)")
    steps = net > 0
    if steps.any() and (~steps).any():
        print(f"callbacks with a network step: {steps.mean() * 100:.0f} %, callback p50 "
              f"{np.percentile(cb[steps], 50):.0f} µs (network {np.percentile(net[steps] * 1e-3, 50):.0f} µs); "
              f"without: p50 {np.percentile(cb[~steps], 50):.0f} µs")
    busy = (cb.sum() * 1e-6 + (diag[:, 1] - diag[:, 0]).sum() * 1e-9) / duration
    gen = Counter(gcs[:, 2].tolist())
    gcd = (gcs[:, 1] - gcs[:, 0]) * 1e-3
    print(f"callbacks busy {busy * 100:.1f} % of the run; diagnostics: {len(diag)} runs, mean "
          f"{np.mean(diag[:, 1] - diag[:, 0]) * 1e-3 if len(diag) else 0:.0f} µs, max "
          f"{np.max(diag[:, 1] - diag[:, 0]) * 1e-3 if len(diag) else 0:.0f} µs")
    if len(gcd):
        print(f"garbage collections: {len(gcd)} ({dict(sorted(gen.items()))} by generation), mean {gcd.mean():.0f} µs, "
              f"max {gcd.max():.0f} µs, total {gcd.sum() * 1e-3:.1f} ms")
    nxt = t_in[1:] - t_out[:-1]
    backlog = t_sent[1:] < t_out[:-1]
    if backlog.any():
        print(f"executor dispatch between back-to-back callbacks (next message already sent): p50 "
              f"{np.percentile(nxt[backlog], 50) * 1e-3:.0f} µs, p99 {np.percentile(nxt[backlog], 99) * 1e-3:.0f} µs "
              f"({backlog.sum()} times)")


# -- py-spy -----------------------------------------------------------------------------------------------------
CATEGORIES = (  # (category, patterns in a frame); a stack goes to the first category a frame matches, frames
    # checked from the leaf to the root
    ("network (ONNX Runtime)", ("onnxruntime", "run_with_iobinding", "_run_rows", "network.py")),
    ("composition", ("_compose_one", "combine", "_combine_row", "ensemble.py", "heading.py", "holes.py")),
    ("estimator planning", ("grid.py", "bias.py", "_plan_", "riann.py", "vqf", "madgwick.py", "mahony.py")),
    ("input gate and stream", ("stream.py", "input.py")),
    ("diagnostics", ("_publish_diagnostics", "_diagnostic_level", "percentile")),
    ("publish", ("publisher.py", "_publish")),
    ("logging", ("logging.py", "get_logger", "_log_gate_result", "_warn_throttled", "rcutils_log")),
    ("callback (node_base)", ("node_base.py", "frames.py", "stamps.py")),
    ("executor (rclpy)", ("executors.py", "task.py", "rclpy", "_rclpy")),
)


def categorise(stack: list[str]) -> str:
    for f in reversed(stack):
        for name, pats in CATEGORIES:
            if any(p in f for p in pats):
                return name
    return "other"


def py_spy_run(h: Harness, args: argparse.Namespace) -> None:
    spy = Path(sys.executable).parent / "py-spy"
    if not spy.exists():
        print("\npy-spy not installed in this environment (pip install py-spy): sampling profile skipped")
        return
    node = str(BIN / f"{args.node}_node")
    raw = Path(tempfile.mkdtemp()) / "py-spy.txt"
    procs: list[subprocess.Popen[bytes]] = []

    def attach(pid: int) -> None:
        h.on_connected = None
        procs.append(subprocess.Popen([str(spy), "record", "--pid", str(pid), "--rate", "1000", "--nonblocking",
                                       "--format", "raw", "--duration", str(int(args.py_spy)),
                                       "--output", str(raw)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE))

    h.on_connected = attach
    r = h.run([node, "--ros-args", "-p", f"nominal_rate:={args.rate}"], args.rate, args.py_spy + 3.0)
    for p in procs:
        err = p.communicate(timeout=60)[1].decode()
        if p.returncode:
            print(f"py-spy failed: {err.strip()[-400:]}")
            return
    counts: Counter[str] = Counter()
    for line in raw.read_text().splitlines():
        stack, _, n = line.rpartition(" ")
        frames = stack.split(";")
        counts[categorise(frames)] += int(n)
    total = sum(counts.values())
    print(f"\n## py-spy: {args.node}_node (installed), {args.rate:.0f} Hz, {args.py_spy:.0f} s sampled at 1 kHz "
          f"(non-blocking; busy threads only: the CPU); run: dropped {r['dropped']:.0f}, "
          f"e2e p99 {r['e2e_p99_us']:.0f} µs")
    print(f"{total} samples")
    print("| category | share of samples % |")
    print("|---|---:|")
    for k, v in counts.most_common():
        print(f"| {k} | {v / total * 100:.1f} |")
    print(f"raw stacks: {raw}")


# -- EventsExecutor check -----------------------------------------------------------------------------------------
ECHO = """
import sys, rclpy
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
if sys.argv[1] == "events":
    from rclpy.experimental import EventsExecutor
    ex = EventsExecutor()
else:
    from rclpy.executors import SingleThreadedExecutor
    ex = SingleThreadedExecutor()
ex.add_node(n)
try:
    ex.spin()
except KeyboardInterrupt:
    pass
"""


def check_events(h: Harness, args: argparse.Namespace) -> None:
    print(f"\n## EventsExecutor check: echo node, {args.check_events} messages at {args.rate:.0f} Hz")
    for kind in ("single", "events"):
        r = h.run([sys.executable, "-c", ECHO, kind], args.rate, args.check_events / args.rate)
        print(f"{kind:7s}: sent {r['sent']:.0f}, received {r['received']:.0f}, e2e p50 {r['e2e_p50_us']:.0f} µs, "
              f"p99 {r['e2e_p99_us']:.0f} µs")


# -- the executor's cost per message ------------------------------------------------------------------------------
def executor_cost(messages: int, reps: int) -> None:
    """Per message: SingleThreadedExecutor.spin_once with a trivial callback and the messages already queued, for
    nodes with more or fewer entities, against taking the same messages without the executor."""
    import rclpy
    from rclpy.event_handler import SubscriptionEventCallbacks
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import Imu
    from std_srvs.srv import Trigger

    qos = QoSProfile(depth=messages, reliability=ReliabilityPolicy.RELIABLE)
    src = rclpy.create_node("executor_cost_source")
    pub = src.create_publisher(Imu, "executor_cost", qos)
    print(f"\n## executor cost: {messages} queued messages, trivial callback, {reps} repetitions (µs per message)")
    print("| node | entities | spin_once min | spin_once median | take without executor min | median |")
    print("|---|---|---:|---:|---:|---:|")
    kinds = {"bare": "one subscription, no parameter services, no QoS event handlers",
             "default": "one subscription, parameter services (rclpy's default node)",
             "riann_like": "+ a 1 s timer, a service, a second subscription, two publishers"}
    for kind, what in kinds.items():
        node = rclpy.create_node(f"executor_cost_{kind}", start_parameter_services=kind != "bare")
        got = Counter[str]()
        events = {"event_callbacks": SubscriptionEventCallbacks(use_default_callbacks=False)} if kind == "bare" else {}
        sub = node.create_subscription(Imu, "executor_cost", lambda m, c=got: c.update("n"), qos, **events)
        if kind == "riann_like":
            node.create_timer(1.0, lambda: None)
            node.create_service(Trigger, "~/reset", lambda req, resp: resp)
            node.create_subscription(Imu, "executor_cost_other", lambda m: None, qos)
            node.create_publisher(Imu, "executor_cost_a", qos)
            node.create_publisher(Imu, "executor_cost_b", qos)
        ex = SingleThreadedExecutor()
        ex.add_node(node)
        end = time.monotonic() + 10
        while pub.get_subscription_count() == 0 and time.monotonic() < end:
            time.sleep(0.05)
        time.sleep(1.0)
        spin, take = [], []
        msg = Imu()
        for _ in range(reps + 1):  # the first repetition warms up and is not counted
            for _i in range(messages):
                pub.publish(msg)
            time.sleep(0.5)
            got.clear()
            t0 = time.perf_counter()
            while got["n"] < messages and time.perf_counter() - t0 < 30:
                ex.spin_once(timeout_sec=0.5)
            spin.append((time.perf_counter() - t0) / max(got["n"], 1) * 1e6)
            for _i in range(messages):
                pub.publish(msg)
            time.sleep(0.5)
            k = 0
            t0 = time.perf_counter()
            while k < messages and time.perf_counter() - t0 < 30:
                k += sub.handle.take_message(Imu, False) is not None
            take.append((time.perf_counter() - t0) / max(k, 1) * 1e6)
        spin, take = spin[1:], take[1:]
        print(f"| {kind} | {what} | {min(spin):.0f} | {np.median(spin):.0f} | {min(take):.0f} | "
              f"{np.median(take):.0f} |")
        ex.remove_node(node)
        ex.shutdown()
        node.destroy_node()
    src.destroy_node()


def main() -> int:
    if "--child" in sys.argv:
        i = sys.argv.index("--child")
        node = NODES[sys.argv[sys.argv.index("--node") + 1]]
        return child(sys.argv[i + 1], node, sys.argv[sys.argv.index("--executor") + 1], "--gc-freeze" in sys.argv)
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rate", type=float, default=1000.0)
    ap.add_argument("--duration", type=float, default=30.0, help="seconds of the timed run (0 = skip it)")
    ap.add_argument("--node", default="riann", choices=sorted(NODES))
    ap.add_argument("--executor", default="single", choices=("single", "events"))
    ap.add_argument("--gc-freeze", action="store_true", help="timed run: gc.collect(); gc.freeze() after start-up")
    ap.add_argument("--py-spy", type=float, default=0.0, help="seconds of the sampling profile (0 = skip it)")
    ap.add_argument("--check-events", type=int, default=0, help="messages of the EventsExecutor check (0 = skip)")
    ap.add_argument("--executor-cost", type=int, default=0, help="queued messages per repetition of the executor's "
                    "cost per message (0 = skip)")
    args = ap.parse_args()
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    print(f"load average at start: {os.getloadavg()[0]:.1f}")
    import rclpy

    if args.executor_cost:  # first, and without the harness (its spin thread would compete for the GIL)
        rclpy.init()
        try:
            executor_cost(args.executor_cost, 3)
        finally:
            rclpy.shutdown()
    if args.duration or args.py_spy or args.check_events:
        h = Harness()
        try:
            if args.duration:
                timed_run(h, args)
            if args.py_spy:
                py_spy_run(h, args)
            if args.check_events:
                check_events(h, args)
        finally:
            h.ex.shutdown()
            h.spinner.join(timeout=5.0)
            h.node.destroy_node()
            rclpy.shutdown()
    print(f"load average at the end: {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
