#!/usr/bin/env python3
"""Soak / load benchmark of the four estimator nodes over real DDS.

    .venv/bin/python bench/soak_nodes.py [--nodes riann,madgwick,mahony,vqf] [--rates 200,1000]
        [--duration 600] [--probe-rates 2000,4000,8000] [--probe-duration 20]
        [--side-by-side-rate 1000] [--side-by-side-duration 600] [--domain 61] [--json out.json]

Per node and input rate it starts the installed executable (``.venv/bin/<node>``, default parameters
except ``nominal_rate``, so input QoS is ``sensor_data``), publishes synthetic IMU samples on a fixed
schedule from a **separate publisher process** (reliable writer, header stamp = schedule) and collects
the node's attitude output here. Reported:

* messages in (published) vs out (attitude messages received), drops = in − out;
* latency p50 / p99 / max: the publisher's CLOCK_MONOTONIC just before ``publish()`` → arrival of the
  output in this process's callback (same clock). It includes two DDS hops and two rclpy callbacks
  (the node's and this collector's), not only the estimator;
* the node's CPU share over the publishing window from ``/proc/<pid>/stat`` (utime + stime; 100 % =
  one core);
* the node's resident memory (VmRSS) after connecting, 10 s into the run, and at the end; growth =
  end − 10 s (the target is < 5 MB over a 10-minute run).

``--probe-rates`` runs short probes above the listed rates to find each node's highest sustained rate
(sustained: ≤ 0.1 % drops, p99 latency < 50 ms, and the publisher achieved ≥ 98 % of the rate).
``--side-by-side-duration`` runs all listed nodes at once on one input stream.

Every run sets ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and its own ROS_DOMAIN_ID (``--domain``,
default 61), is bounded in time, and stops its nodes itself (SIGINT, then SIGKILL after 10 s).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import platform
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

from riann_ros import defaults, stamps

BIN = Path(sys.executable).parent
TOPICS = {
    "riann_node": "imu/attitude",
    "madgwick_node": "imu/madgwick/attitude",
    "mahony_node": "imu/mahony/attitude",
    "vqf_node": "imu/vqf/attitude",
}
CLK_TCK = os.sysconf("SC_CLK_TCK")


# ---- the publisher process -------------------------------------------------------------------------


def publisher_main(rate: float, n: int, stamp0: int, pub_times, n_subs: int, ready, go, state) -> None:
    import rclpy
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import Imu

    from riann_ros.datasets.synthetic import generate

    rec = generate(rate=rate, duration=min(60.0, n / rate + 1), seed=7)
    acc, gyr = rec.acc.tolist(), rec.gyr.tolist()
    m = len(acc)
    rclpy.init()
    node = rclpy.create_node("soak_imu_driver")
    pub = node.create_publisher(Imu, "imu/data_raw", QoSProfile(depth=1000, history=HistoryPolicy.KEEP_LAST,
                                                                reliability=ReliabilityPolicy.RELIABLE))
    end = time.monotonic() + 30
    while pub.get_subscription_count() < n_subs and time.monotonic() < end:
        time.sleep(0.01)
    ready.set()
    go.wait()
    msg = Imu()
    msg.header.frame_id = defaults.IMU_FRAME
    msg.orientation_covariance[0] = -1.0
    times = np.frombuffer(pub_times, dtype=np.int64)
    period_ns = 1e9 / rate
    t_start = time.monotonic_ns()
    mono = time.monotonic_ns
    for i in range(n):
        due = t_start + int(i * period_ns)
        while True:
            now = mono()
            ahead = due - now
            if ahead <= 0:
                break
            if ahead > 1_500_000:
                time.sleep((ahead - 1_000_000) * 1e-9)
        k = i % m
        stamps.set_ns(msg.header.stamp, stamp0 + int(i * period_ns))
        a, g = acc[k], gyr[k]
        la, av = msg.linear_acceleration, msg.angular_velocity
        la.x, la.y, la.z = a
        av.x, av.y, av.z = g
        times[i] = mono()
        pub.publish(msg)
    state.value = (mono() - t_start) / 1e9  # publishing time
    time.sleep(3.0)  # let the last messages be delivered before the writer goes away
    node.destroy_node()
    rclpy.shutdown()


# ---- node process statistics -----------------------------------------------------------------------


def proc_cpu_ticks(pid: int) -> int:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return int(fields[11]) + int(fields[12])  # utime, stime (fields 14 and 15 of stat)


def proc_rss_mb(pid: int) -> float:
    for ln in Path(f"/proc/{pid}/status").read_text().splitlines():
        if ln.startswith("VmRSS:"):
            return int(ln.split()[1]) / 1024
    return float("nan")


# ---- one run ---------------------------------------------------------------------------------------


def run(nodes: list[str], rate: float, duration: float, logdir: Path) -> list[dict]:
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import QuaternionStamped
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    n = round(rate * duration)
    stamp0 = time.time_ns()
    period_ns = 1e9 / rate
    ctx = mp.get_context("spawn")
    pub_times = ctx.RawArray("q", n)
    times = np.frombuffer(pub_times, dtype=np.int64)
    ready, go, state = ctx.Event(), ctx.Event(), ctx.Value("d", 0.0)

    procs = {}
    for name in nodes:
        log = (logdir / f"{name}_{rate:g}.log").open("w")
        procs[name] = subprocess.Popen([str(BIN / name), "--ros-args", "-p", f"nominal_rate:={float(rate)!r}"],
                                       stdout=log, stderr=subprocess.STDOUT, env=os.environ.copy())
    rctx = rclpy.Context()
    rclpy.init(context=rctx)
    cnode = rclpy.create_node("soak_collector", context=rctx)
    ex = SingleThreadedExecutor(context=rctx)
    ex.add_node(cnode)
    lat = {name: np.full(n, np.nan) for name in nodes}
    stats = {name: {"out": 0, "reordered": 0, "last": -1} for name in nodes}

    def make_cb(name):
        arr, s = lat[name], stats[name]

        def cb(m) -> None:
            now = time.monotonic_ns()
            i = round((stamps.to_ns(m.header.stamp) - stamp0) / period_ns)
            s["out"] += 1
            if 0 <= i < n:
                if i <= s["last"]:
                    s["reordered"] += 1
                s["last"] = i
                arr[i] = (now - times[i]) * 1e-6

        return cb

    accepted = {name: 0 for name in nodes}

    def on_diag(m) -> None:
        for st in m.status:
            name = st.name.split(":")[0].strip().lstrip("/")
            if name in accepted:
                for kv in st.values:
                    if kv.key == "samples accepted (total)":
                        accepted[name] = max(accepted[name], int(kv.value))

    cnode.create_subscription(DiagnosticArray, "/diagnostics", on_diag, 100)
    subs = [cnode.create_subscription(QuaternionStamped, TOPICS[name], make_cb(name),
                                      QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
            for name in nodes]
    th = threading.Thread(target=ex.spin, daemon=True)
    th.start()
    pub = ctx.Process(target=publisher_main, args=(rate, n, stamp0, pub_times, len(nodes), ready, go, state))
    pub.start()
    results = []
    try:
        end = time.monotonic() + 40
        while not (ready.is_set() and all(s.get_publisher_count() > 0 for s in subs)):
            if time.monotonic() > end:
                raise RuntimeError(f"nodes did not connect; see logs in {logdir}")
            time.sleep(0.05)
        time.sleep(1.0)
        rss_connect = {k: proc_rss_mb(p.pid) for k, p in procs.items()}
        cpu0 = {k: proc_cpu_ticks(p.pid) for k, p in procs.items()}
        t0 = time.monotonic()
        go.set()
        rss_10 = {}
        rss_series = {k: [] for k in nodes}
        while pub.is_alive() and state.value == 0.0:
            time.sleep(0.5)
            el = time.monotonic() - t0
            if not rss_10 and el >= min(10.0, duration / 2):
                rss_10 = {k: proc_rss_mb(p.pid) for k, p in procs.items()}
            if int(el) % 30 == 0:
                for k, p in procs.items():
                    rss_series[k].append((round(el), round(proc_rss_mb(p.pid), 1)))
        wall = time.monotonic() - t0
        cpu1 = {k: proc_cpu_ticks(p.pid) for k, p in procs.items()}
        rss_end = {k: proc_rss_mb(p.pid) for k, p in procs.items()}
        pub.join(10)
        time.sleep(1.5)  # one more /diagnostics period
        pub_s = state.value or wall
        sent = int((times > 0).sum())
        for name in nodes:
            lt = lat[name][~np.isnan(lat[name])]
            s = stats[name]
            results.append({
                "node": name, "side_by_side": len(nodes) > 1, "rate_hz": rate, "duration_s": duration,
                "in": sent, "achieved_rate_hz": round(sent / pub_s, 1), "node_accepted": accepted[name],
                "out": s["out"],
                "drops": sent - s["out"], "drop_pct": round(100 * (sent - s["out"]) / max(sent, 1), 3),
                "reordered": s["reordered"],
                "lat_p50_ms": round(float(np.percentile(lt, 50)), 3) if len(lt) else None,
                "lat_p99_ms": round(float(np.percentile(lt, 99)), 3) if len(lt) else None,
                "lat_max_ms": round(float(lt.max()), 1) if len(lt) else None,
                "cpu_pct": round(100 * (cpu1[name] - cpu0[name]) / CLK_TCK / wall, 1),
                "rss_connect_mb": round(rss_connect[name], 1), "rss_10s_mb": round(rss_10.get(name, np.nan), 1),
                "rss_end_mb": round(rss_end[name], 1),
                "rss_growth_mb": round(rss_end[name] - rss_10.get(name, np.nan), 1),
                "rss_series": rss_series[name],
                "lat_p99_by_tenth_ms": [round(float(np.nanpercentile(c, 99)), 2) if np.isfinite(c).any() else None
                                        for c in np.array_split(lat[name], 10)],
            })
    finally:
        for p in procs.values():
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
        for p in procs.values():
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        if pub.is_alive():
            pub.kill()
        ex.shutdown()
        th.join(5)
        cnode.destroy_node()
        rctx.try_shutdown()
    return results


def sustained(r: dict) -> bool:
    return (r["drop_pct"] <= 0.1 and r["lat_p99_ms"] is not None and r["lat_p99_ms"] < 50
            and r["achieved_rate_hz"] >= 0.98 * r["rate_hz"])


def row(r: dict, label: str = "") -> str:
    label = label or f"{r['rate_hz']:g} Hz"
    return (f"| {r['node']} | {label} | {r['duration_s']:g} s | {r['in']:,} | "
            f"{r['achieved_rate_hz']:,.0f} | {r['node_accepted']:,} | {r['out']:,} | "
            f"{r['drops']:,} ({r['drop_pct']:.2f} %) | "
            f"{r['reordered']} | {r['lat_p50_ms']} | {r['lat_p99_ms']} | {r['lat_max_ms']} | {r['cpu_pct']} | "
            f"{r['rss_connect_mb']} / {r['rss_10s_mb']} / {r['rss_end_mb']} | {r['rss_growth_mb']:+} |")


COLUMNS = ["node", "input", "duration", "in", "achieved Hz", "node got", "out", "drops", "reordered", "p50 ms",
           "p99 ms", "max ms", "CPU %", "RSS MB connect / 10 s / end", "growth MB"]
HEADER = ("| " + " | ".join(COLUMNS) + " |\n|---|---|---|" + "---:|" * 10 + "---|---:|")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--nodes", default="riann,madgwick,mahony,vqf")
    ap.add_argument("--rates", default="200,1000", help="input rates (Hz) of the soak runs; empty to skip")
    ap.add_argument("--duration", type=float, default=600.0, help="s per soak run")
    ap.add_argument("--probe-rates", default="2000,4000,8000", help="rates probed for the highest sustained one")
    ap.add_argument("--probe-duration", type=float, default=20.0)
    ap.add_argument("--side-by-side-rate", type=float, default=1000.0)
    ap.add_argument("--side-by-side-duration", type=float, default=600.0, help="0 to skip")
    ap.add_argument("--domain", type=int, default=61, help="ROS_DOMAIN_ID of this benchmark")
    ap.add_argument("--json", type=Path, default=None, help="write all results here")
    ap.add_argument("--logdir", type=Path, default=None, help="node logs (default: a temporary directory)")
    args = ap.parse_args()
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ["ROS_DOMAIN_ID"] = str(args.domain)
    os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
    import tempfile

    logdir = args.logdir or Path(tempfile.mkdtemp(prefix="soak_logs_"))
    logdir.mkdir(parents=True, exist_ok=True)
    nodes = [f"{x.strip()}_node" for x in args.nodes.split(",") if x.strip()]
    rates = [float(x) for x in args.rates.split(",") if x.strip()]
    probes = [float(x) for x in args.probe_rates.split(",") if x.strip()]
    print(f"# {platform.node()} {platform.machine()}, {os.cpu_count()} CPUs, python {platform.python_version()}, "
          f"ROS_DOMAIN_ID={args.domain}, load average {os.getloadavg()[0]:.2f}; logs in {logdir}", flush=True)
    print(HEADER, flush=True)
    allres: list[dict] = []
    for name in nodes:
        for rate in rates:
            for r in run([name], rate, args.duration, logdir):
                allres.append(r)
                print(row(r), flush=True)
        best = None
        for rate in probes:
            (r,) = run([name], rate, args.probe_duration, logdir)
            r["probe"] = True
            allres.append(r)
            ok = sustained(r)
            print(row(r, f"{rate:g} Hz probe{'' if ok else ' (not sustained)'}"), flush=True)
            if not ok:
                break
            best = rate
        if probes:
            allres.append({"node": name, "highest_sustained_hz": best, "probed": probes})
            print(f"<!-- {name}: highest sustained probed rate {best} Hz -->", flush=True)
    if args.side_by_side_duration > 0 and len(nodes) > 1:
        for r in run(nodes, args.side_by_side_rate, args.side_by_side_duration, logdir):
            allres.append(r)
            print(row(r, f"{args.side_by_side_rate:g} Hz, all {len(nodes)} at once"), flush=True)
    print(f"# load average after {os.getloadavg()[0]:.2f}", flush=True)
    if args.json:
        args.json.write_text(json.dumps(allres, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
