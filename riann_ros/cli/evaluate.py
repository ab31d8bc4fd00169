"""``riann-bag-eval``: score attitude estimators on dataset bags the paper's way.

Example::

    riann-bag-eval bags/*.mcap --estimators riann,madgwick:beta=0.033,mahony:kp=1:ki=0.3,vqf \\
        --scenarios all --seed 0 --jobs 2 --out eval_out

Inputs are rosbag2 bags in the layout of :mod:`riann_ros.bagio` (``.mcap`` files or bag directories) or
BROAD trial files (``.hdf5`` / ``.mat``). Exit status: 0 all inputs evaluated, 1 some input failed
(named on stderr, the others are still evaluated and reported), 2 bad command line.
"""

from __future__ import annotations

import argparse
import contextlib
import re
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from riann_ros import evaluation as ev
from riann_ros import report

DEFAULT_ESTIMATORS = "riann,madgwick,mahony,vqf"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="riann-bag-eval",
        description="Attitude RMSE (e_α, heading ignored) of RIANN, Madgwick, Mahony and VQF on dataset bags, "
        "in the paper's restrictive / partially-restrictive / realistic scenarios.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="estimator specs: NAME[:PARAM=VALUE[:PARAM=VALUE...]], comma-separated, e.g.\n"
        "  riann,madgwick:beta=0.033,madgwick:beta=0.1,mahony:kp=1:ki=0.3,vqf:tau_acc=3\n"
        "tuning specs: NAME (default grid) or NAME:PARAM=V1/V2/...[:PARAM=...], e.g. mahony:kp=0.5/1/2:ki=0/0.3\n"
        "exit status: 0 ok, 1 some input failed, 2 usage error",
    )
    p.add_argument("inputs", nargs="+", metavar="BAG", help="bags (.mcap, bag directories) or BROAD .hdf5/.mat files")
    p.add_argument(
        "--estimators",
        "-e",
        default=None,
        help=f"estimator specs (default: those of {DEFAULT_ESTIMATORS} that are installed)",
    )
    p.add_argument(
        "--scenarios",
        "-s",
        default="all",
        help="restrictive, partially-restrictive, realistic or all (comma-separated; default all)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the random gyro bias (per sequence: seed + name)")
    p.add_argument(
        "--rates",
        default=None,
        help="comma-separated sampling rates (Hz) to resample to (FFT), e.g. 50,100,200,500; "
        "'native' keeps the recording's own rate. Native-rate runs stream bags chunk by chunk (memory independent "
        "of the bag length); resampled runs and --write-estimates load each input whole",
    )
    p.add_argument("--jobs", "-j", type=int, default=1, help="parallel worker processes (one per sequence)")
    p.add_argument(
        "--out",
        "-o",
        type=Path,
        default=None,
        help="write results.csv, results.json, report.md and plots (PNG+SVG) here",
    )
    p.add_argument("--heading", action="store_true", help="also score heading and total error (extra columns)")
    p.add_argument(
        "--plot-sequence", default=None, help="sequence name for the error-over-time plot (default: the first input)"
    )
    p.add_argument("--no-plots", action="store_true", help="skip the plots")
    p.add_argument(
        "--tune",
        action="append",
        default=[],
        metavar="SPEC",
        help="grid-search this estimator's parameters for the lowest mean RMSE on the inputs and add "
        "the best one to the comparison (repeatable)",
    )
    p.add_argument("--tune-scenario", default=ev.REALISTIC, help="scenario the tuning minimises (default realistic)")
    p.add_argument(
        "--write-estimates",
        type=Path,
        default=None,
        metavar="DIR",
        help="write a copy of every input bag into DIR with each estimator's output as "
        "geometry_msgs/QuaternionStamped topics /eval/<scenario>/<estimator> (first scenario)",
    )
    p.add_argument("--force", action="store_true", help="overwrite existing --write-estimates outputs")
    p.add_argument(
        "--live",
        action="store_true",
        help="replay the inputs over DDS to the estimator nodes (started by the tool, or already running with "
        "--live-topics) instead of running them in-process; reports messages lost",
    )
    p.add_argument("--speed", type=float, default=1.0, help="--live replay speed factor (0: as fast as the nodes go)")
    p.add_argument(
        "--live-input", default=None, help="--live: IMU topic to publish on (default /riann_eval/imu/data_raw)"
    )
    p.add_argument(
        "--live-topics",
        default=None,
        help="--live with nodes already running: their attitude topics, comma-separated, in --estimators order "
        "(they must subscribe to --live-input)",
    )
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bar")
    return p


def _parse_rates(text: str | None) -> list[float | None]:
    if not text:
        return [None]
    out: list[float | None] = []
    for item in text.split(","):
        item = item.strip().lower()
        if not item:
            continue
        if item == "native":
            out.append(None)
            continue
        r = float(item)
        if not r > 0:
            raise ValueError(f"rate must be positive, got {item}")
        out.append(r)
    return out or [None]


def topic_for(scenario: str, label: str) -> str:
    """A valid ROS topic name for an estimator's estimates."""
    clean = re.sub(r"[^A-Za-z0-9_]+", "_", label).strip("_")
    return f"/eval/{scenario.replace('-', '_')}/{clean}"


def _err(msg: str) -> None:
    print(f"riann-bag-eval: {msg}", file=sys.stderr)


def _run_tuning(args, sources: list[str], settings: ev.EvalSettings, quiet: bool) -> tuple[list[dict], list]:
    tuning, extra = [], []
    for text in args.tune:
        name, grid = ev.parse_grid(text)
        specs = ev.grid_specs(name, grid)
        tset = ev.EvalSettings(estimators=specs, scenarios=[args.tune_scenario], seed=settings.seed, rates=[None])
        if not quiet:
            print(
                f"tuning {name}: {len(specs)} combinations on {len(sources)} input(s), {args.tune_scenario}",
                file=sys.stderr,
            )
        results = ev.evaluate_sources(sources, tset, args.jobs, report.Progress(len(sources), enabled=not quiet))
        rows = [r for res in results if not res.error for r in res.rows]
        best = ev.best_of(rows, specs, args.tune_scenario)
        best["estimator"] = name
        tuning.append(best)
        b = best["best"]
        label = f"{ev.make_label(name, b['params'])} tuned"
        extra.append(ev.EstimatorSpec(name, tuple(b["params"].items()), label))
        print(
            f"tuned {name} on {args.tune_scenario}: {b['label']} mean {b['mean']:.2f}° max {b['max']:.2f}°",
            file=sys.stderr,
        )
    return tuning, extra


def _write_estimates(results: list[ev.SequenceResult], out_dir: Path, force: bool) -> list[str]:
    from riann_ros import bagio

    problems = []
    out_dir.mkdir(parents=True, exist_ok=True)
    for res in results:
        if res.error or not res.estimates:
            continue
        src = Path(res.source)
        if src.suffix.lower() in ev.BROAD_SUFFIXES:
            problems.append(f"{src}: --write-estimates needs a bag input, not a dataset file")
            continue
        est = res.estimates
        topics = {topic_for(est["scenario"], lbl): (est["stamps"], q) for lbl, q in est["quats"].items()}
        dst = out_dir / src.name
        try:
            bagio.write_estimates(src, dst, topics, force=force)
            print(f"wrote {dst} ({', '.join(topics)})", file=sys.stderr)
        except Exception as exc:
            problems.append(f"{src}: cannot write estimates to {dst}: {exc}")
    return problems


def main(argv: list[str] | None = None) -> int:
    """The CLI. Ctrl-C (SIGINT) exits with status 130 and a one-line message, leaving no result files of
    this run (files being written when it came are removed)."""
    try:
        return _main(argv)
    except KeyboardInterrupt:
        for f in _WRITING:
            f.unlink(missing_ok=True)
        _err("interrupted; no results written" + (" (partly written result files removed)" if _WRITING else ""))
        return 130
    finally:
        _WRITING.clear()


_WRITING: list[Path] = []  # result files of this run while they are being written


def _main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    argv_list = sys.argv[1:] if argv is None else list(argv)
    if args.live and (args.tune or args.jobs > 1 or args.write_estimates):
        _err("--live runs one replay at a time: it does not combine with --tune, --jobs or --write-estimates")
        return 2
    try:
        spec_text = args.estimators or ",".join(
            n for n in DEFAULT_ESTIMATORS.split(",") if n in ev.available_estimators()
        )
        estimators = ev.parse_estimators(spec_text)
        scenarios = ev.parse_scenarios(args.scenarios)
        rates = _parse_rates(args.rates)
        if args.tune_scenario not in ev.SCENARIOS:
            raise ValueError(f"unknown --tune-scenario {args.tune_scenario!r}; known: {', '.join(ev.SCENARIOS)}")
        for t in args.tune:
            ev.parse_grid(t)
        if args.jobs < 1:
            raise ValueError("--jobs must be at least 1")
    except (ValueError, ImportError) as exc:
        _err(str(exc))
        return 2
    sources = [str(s) for s in args.inputs]
    quiet = args.quiet
    t_start = time.perf_counter()
    settings = ev.EvalSettings(
        estimators=estimators,
        scenarios=scenarios,
        seed=args.seed,
        rates=rates,
        with_heading=args.heading,
        series_for=None if args.no_plots or not args.out else (args.plot_sequence or "*"),
        keep_estimates=args.write_estimates is not None,
    )
    tuning: list[dict[str, Any]] = []
    if args.tune:
        try:
            tuning, extra = _run_tuning(args, sources, settings, quiet)
        except ev.EvalError as exc:
            _err(f"tuning failed: {exc}")
            return 1
        settings.estimators = [
            *settings.estimators,
            *(s for s in extra if s.label not in {e.label for e in estimators}),
        ]

    if args.live:
        try:
            results = _run_live(args, sources, settings, quiet)
        except ev.EvalError as exc:
            _err(str(exc))
            return 1
    else:
        results = ev.evaluate_sources(sources, settings, args.jobs, report.Progress(len(sources), enabled=not quiet))
    if settings.series_for and settings.series_for != "*" and not any(r.series for r in results):
        _err(f"--plot-sequence {settings.series_for!r} matches no evaluated sequence")
    elapsed = time.perf_counter() - t_start
    failures = [{"source": r.source, "error": r.error} for r in results if r.error]
    for f in failures:
        _err(f"FAILED {f['error']}")
    rows = [row for r in results if not r.error for row in r.rows]
    agg = ev.aggregate(rows)
    print(report.format_table(agg))
    if args.live and rows:
        lost: dict[str, list[int]] = {}
        for row in rows:
            v = lost.setdefault(row["estimator"], [0, 0])
            v[0] += row.get("lost", 0)
            v[1] += row.get("published", 0)
        print("live: messages lost / published: " + ", ".join(f"{k} {a} / {b}" for k, (a, b) in lost.items()))
    print(
        f"\n{len(results) - len(failures)} of {len(results)} input(s) evaluated in {elapsed:.1f} s"
        + (f"; {len(failures)} failed" if failures else "")
    )

    problems: list[str] = []
    if args.write_estimates is not None:
        problems = _write_estimates(results, args.write_estimates, args.force)
        for p in problems:
            _err(p)

    if args.out:
        out = args.out
        out.mkdir(parents=True, exist_ok=True)
        settings_dict = {
            "command": "riann-bag-eval " + shlex.join(argv_list),
            "inputs": sources,
            "estimators": [e.to_dict() for e in settings.estimators],
            "scenarios": scenarios,
            "seed": args.seed,
            "rates": rates,
            "jobs": args.jobs,
            "bias_std_dps": ev.BIAS_STD_DPS,
            "scenario_definition": {
                ev.RESTRICTIVE: "from the first sample; mean gyro over the initial rest (samples before the first "
                "scored sample) subtracted",
                ev.PARTIAL: "restrictive + constant gyro bias per axis ~ N(0, 0.5 deg/s), seeded per sequence "
                "(sha256 of '<seed>:<sequence name>')",
                ev.REALISTIC: "partially-restrictive signals (same bias) starting at the first scored sample",
            },
            "metric": "RMSE of e_alpha = 2 acos(sqrt(w^2+z^2)) of q_ref * conj(q_est), deg, over score mask & "
            "reference present & estimate present",
        }
        payload = {
            "settings": settings_dict,
            "versions": report.versions(),
            "elapsed_s": elapsed,
            "summary": agg,
            "sequences": [
                {
                    "source": r.source,
                    "name": r.name,
                    "dataset": r.dataset,
                    "seconds": r.seconds,
                    "cpu_seconds": r.cpu_seconds,
                    "scenarios": r.scenarios,
                }
                for r in results
                if not r.error
            ],
            "results": rows,
            "tuning": tuning,
            "failures": failures,
        }
        _WRITING[:] = [
            out / f"{stem}.{ext}"
            for stem in ("rmse_boxplots", "error_over_time", "rmse_vs_rate")
            for ext in ("png", "svg")
        ]
        _WRITING.extend([out / "results.csv", out / "results.json", out / "report.md"])
        report.write_csv(out / "results.csv", rows)
        report.write_json(out / "results.json", payload)
        plots: list[Path] = []
        if not args.no_plots and rows:
            plots += report.plot_boxes(rows, out)
            series = next((r.series for r in results if r.series), None)
            if series:
                plots += report.plot_error_over_time(series, out)
            plots += report.plot_rmse_vs_rate(rows, out)
        sources_text = sorted({r.citation for r in results if r.citation and not r.error})
        report.write_markdown(out / "report.md", agg, rows, settings_dict, failures, plots, tuning, sources_text)
        _WRITING.clear()
        print(f"wrote {out}/results.csv, results.json, report.md" + (f" and {len(plots)} plot files" if plots else ""))
    return 1 if failures or problems else 0


if __name__ == "__main__":
    sys.exit(main())


# ---------------------------------------------------------------------------------------------------
# --live: replay over DDS to the estimator nodes
# ---------------------------------------------------------------------------------------------------
LIVE_NS = "/riann_eval"
LIVE_GAP_NS = 2_000_000_000  # stamp gap between replays (> the nodes' max_dt): each replay restarts them


def _ros_param(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)  # keeps the decimal point: the nodes declare float parameters
    return str(value)


def _node_topics(name: str) -> tuple[str, str]:
    """(attitude topic, imu output topic) of the ``<name>_node`` class, to remap them."""
    import importlib

    from riann_ros.nodes.node_base import EstimatorNode

    mod = importlib.import_module(f"riann_ros.nodes.{name}_node")
    for obj in vars(mod).values():
        if isinstance(obj, type) and issubclass(obj, EstimatorNode) and obj.ESTIMATOR == name:
            return obj.ATTITUDE_TOPIC, obj.IMU_TOPIC
    return "imu/attitude", "imu/data"


def _node_executable(name: str) -> str:
    exe = Path(sys.executable).parent / f"{name}_node"
    if exe.exists():
        return str(exe)
    found = shutil.which(f"{name}_node")
    if found is None:
        raise ev.EvalError(f"--live: {name}_node is not installed (run make setup)")
    return found


class LiveRunner:
    """Replays scenario recordings over DDS to one node per estimator and collects what they publish.

    With ``start_nodes`` the tool starts ``<name>_node`` per spec (input remapped to
    ``/riann_eval/imu/data_raw``, output to ``/riann_eval/<i>/attitude``, reliable QoS) with the
    recording's rate as ``nominal_rate``; otherwise ``topics`` name the attitude topics of nodes already
    running on ``input_topic``. Consecutive replays are separated by a stamp gap larger than the nodes'
    ``max_dt`` so every replay starts the estimators afresh, as offline. Publishing is paced at ``speed``
    × real time (0: as fast as the slowest node keeps up) with at most ``window`` samples in flight.
    """

    mode = "live"

    def __init__(
        self,
        speed: float = 1.0,
        window: int = 200,
        input_topic: str | None = None,
        topics: list[str] | None = None,
        log_dir: Path | None = None,
    ) -> None:
        import rclpy
        from geometry_msgs.msg import QuaternionStamped
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import Imu

        self.speed = speed
        self.window = window
        self.external = topics
        self.input_topic = input_topic or f"{LIVE_NS}/imu/data_raw"
        self.log_dir = log_dir or Path(tempfile.mkdtemp(prefix="riann_live_"))
        self._Imu, self._Quat = Imu, QuaternionStamped
        self._qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        self._ctx = rclpy.context.Context()
        rclpy.init(context=self._ctx)
        self.node = rclpy.create_node("riann_bag_eval_live", context=self._ctx)
        self._pub = self.node.create_publisher(Imu, self.input_topic, self._qos)
        self._exec = SingleThreadedExecutor(context=self._ctx)
        self._exec.add_node(self.node)
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()
        self._procs: list[subprocess.Popen] = []
        self._subs: list[Any] = []
        self._got: list[list[tuple[int, float, float, float, float]]] = []
        self._next_stamp = 1_000_000_000
        self._started_for: tuple | None = None

    def _spin(self) -> None:
        from rclpy.executors import ExternalShutdownException

        try:
            while self._ctx.ok():
                self._exec.spin_once(timeout_sec=0.05)
        except (ExternalShutdownException, Exception):
            pass

    # -- nodes ----------------------------------------------------------------------------------
    def _subscribe(self, topics: list[str]) -> None:
        for s in self._subs:
            self.node.destroy_subscription(s)
        self._subs, self._got = [], []
        for i, topic in enumerate(topics):
            box: list[tuple[int, float, float, float, float]] = []
            self._got.append(box)

            def cb(m, box=box) -> None:
                q = m.quaternion
                box.append((m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec, q.w, q.x, q.y, q.z))

            self._subs.append(self.node.create_subscription(self._Quat, topic, cb, self._qos))
            del i

    def _ensure_nodes(self, specs: list[ev.EstimatorSpec], rate: float) -> None:
        key = (tuple(specs), round(rate, 6))
        if self._started_for == key:
            return
        if self.external is not None:
            if len(self.external) != len(specs):
                raise ev.EvalError(f"--live-topics gives {len(self.external)} topics for {len(specs)} estimators")
            if self._started_for is None:
                self._subscribe(self.external)
                self._wait_connected(None)
            self._started_for = key
            return
        self.stop_nodes()
        topics = []
        for i, spec in enumerate(specs):
            out = f"{LIVE_NS}/e{i}/attitude"
            att_topic, imu_topic = _node_topics(spec.name)
            cmd = [
                _node_executable(spec.name),
                "--ros-args",
                "-r",
                f"__node:=riann_eval_{i}_{spec.name}",
                "-r",
                f"imu/data_raw:={self.input_topic}",
                "-r",
                f"{att_topic}:={out}",
                "-r",
                f"{imu_topic}:={LIVE_NS}/e{i}/imu",
                "-p",
                "input_qos:=reliable",
                "-p",
                "input_depth:=1000",
                "-p",
                "output_depth:=1000",
                "-p",
                f"nominal_rate:={float(rate)!r}",
                *(a for k, v in spec.params for a in ("-p", f"{k}:={_ros_param(v)}")),
            ]
            with open(self.log_dir / f"node_{i}_{spec.name}.log", "w") as log:  # the child keeps its own fd
                self._procs.append(subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT))
            topics.append(out)
        self._subscribe(topics)
        self._wait_connected(specs)
        self._started_for = key

    def _wait_connected(self, specs: list[ev.EstimatorSpec] | None, timeout: float = 60.0) -> None:
        end = time.monotonic() + timeout
        n = len(self._subs)
        while time.monotonic() < end:
            if self._pub.get_subscription_count() >= n and all(s.get_publisher_count() > 0 for s in self._subs):
                time.sleep(0.3)  # let discovery settle in both directions
                return
            dead = [p for p in self._procs if p.poll() is not None]
            if dead:
                break
            time.sleep(0.05)
        logs = "; ".join(f"{p.name}: {p.read_text()[-300:]}" for p in sorted(self.log_dir.glob("node_*.log")))
        raise ev.EvalError(f"--live: the estimator nodes did not connect ({logs or 'no logs'})")

    def stop_nodes(self) -> None:
        for p in self._procs:
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
        for p in self._procs:
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        self._procs = []
        self._started_for = None

    def close(self) -> None:
        self.stop_nodes()
        with contextlib.suppress(Exception):
            self._ctx.try_shutdown()
        self._thread.join(2)

    # -- one replay -----------------------------------------------------------------------------
    def __call__(self, specs: list[ev.EstimatorSpec], rec: Any) -> list[tuple[np.ndarray, dict[str, Any]]]:
        self._ensure_nodes(specs, rec.rate_hz)
        stamps = rec.stamps_ns - rec.stamps_ns[0] + self._next_stamp
        self._next_stamp = int(stamps[-1]) + LIVE_GAP_NS
        for box in self._got:
            box.clear()
        msg = self._Imu()
        msg.header.frame_id = rec.frame_id
        msg.orientation_covariance[0] = -1.0
        t0 = time.monotonic()
        rel = (stamps - stamps[0]) * 1e-9
        n = len(stamps)
        acc, gyr = rec.acc.tolist(), rec.gyr.tolist()
        for i in range(n):
            if self.speed > 0:
                delay = t0 + rel[i] / self.speed - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
            stall_end = time.monotonic() + 2.0
            while i - min(len(b) for b in self._got) >= self.window and time.monotonic() < stall_end:
                time.sleep(0.0002)
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(stamps[i]), 1_000_000_000)
            a, g = acc[i], gyr[i]
            la, av = msg.linear_acceleration, msg.angular_velocity
            la.x, la.y, la.z = a
            av.x, av.y, av.z = g
            self._pub.publish(msg)
        last = int(stamps[-1])
        idle_end = time.monotonic() + 5.0
        counts = [len(b) for b in self._got]
        while time.monotonic() < idle_end:
            if all(b and b[-1][0] == last for b in self._got):
                break
            time.sleep(0.01)
            now = [len(b) for b in self._got]
            if now != counts:
                counts, idle_end = now, time.monotonic() + 5.0
        wall = time.monotonic() - t0
        index = {int(s): k for k, s in enumerate(stamps)}
        out = []
        for box in self._got:
            q = np.full((n, 4), np.nan)
            unknown = 0
            for s, w, x, y, z in list(box):
                k = index.get(s)
                if k is None:
                    unknown += 1
                else:
                    q[k] = (w, x, y, z)
            received = int(np.isfinite(q).all(axis=1).sum())
            out.append(
                (
                    q,
                    {
                        "seconds": wall,
                        "published": n,
                        "received": received,
                        "lost": n - received,
                        "unexpected": unknown,
                    },
                )
            )
        return out


def _run_live(args, sources: list[str], settings: ev.EvalSettings, quiet: bool) -> list[ev.SequenceResult]:
    try:
        runner = LiveRunner(
            speed=args.speed,
            input_topic=args.live_input,
            topics=args.live_topics.split(",") if args.live_topics else None,
        )
    except ImportError as exc:
        raise ev.EvalError(f"--live needs rclpy and the ROS message packages: {exc}") from exc
    progress = report.Progress(len(sources), enabled=not quiet)
    results = []
    try:
        for i, src in enumerate(sources):
            try:
                rec = ev.load_recording(src)
                res = ev.evaluate_recording(rec, settings, src, runner=runner)
            except ev.EvalError as exc:
                res = ev.SequenceResult(source=src, error=str(exc))
            except Exception as exc:
                res = ev.SequenceResult(source=src, error=f"{src}: {type(exc).__name__}: {exc}")
            results.append(res)
            progress(i + 1, len(sources), res)
    finally:
        runner.close()
    return results
