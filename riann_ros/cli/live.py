"""Live evaluation: replay scenario sequences over DDS to the estimator nodes (``riann-bag-eval --live``).

:class:`LiveRunner` is a runner (:mod:`riann_ros.evaluation.runners`) of the evaluation pipeline: instead of
running the estimators in-process it publishes each scenario sequence as ``sensor_msgs/Imu`` and
collects the nodes' ``QuaternionStamped`` outputs by stamp, chunk by chunk, so the same scoring applies.
"""

from __future__ import annotations

import contextlib
import importlib
import math
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from riann_ros import stamps
from riann_ros.bagio.topics import sigmas_of_variances
from riann_ros.estimators import estimator_class
from riann_ros.evaluation.errors import EvalError
from riann_ros.evaluation.results import RunStats
from riann_ros.evaluation.specs import EstimatorSpec
from riann_ros.gate import GateConfig
from riann_ros.recording import Recording

LIVE_NS = "/riann_eval"
LIVE_MAG_TOPIC = f"{LIVE_NS}/imu/mag"
LIVE_GAP_NS = 2_000_000_000  # stamp gap between replays (> the nodes' max_dt), besides the ~/restart call
IDLE_S = 5.0  # give up waiting for outputs after this long without a new one
MAG_LEAD = 2  # a sample's field is published this many IMU messages ahead of it (there when its IMU message is)

# stamp_ns, w, x, y, z and the orientation variances about x, y, z (rad²; NaN: the topic carries no covariance),
# turned into σ once per piece (sigmas_of_variances), not in the callback
Output = tuple[float, ...]
NO_VARIANCES = (math.nan, math.nan, math.nan)


def ros_param(value: Any) -> str:
    """A parameter value as ``-p name:=value`` text."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)  # keeps the decimal point: the nodes declare float parameters
    if isinstance(value, tuple):  # a float array (mag_hard_iron, mag_soft_iron)
        return "[" + ", ".join(repr(float(v)) for v in value) + "]"
    return str(value)


def node_topics(name: str) -> tuple[str, str]:
    """(attitude topic, imu output topic) of the ``<name>_node`` class, to remap them."""
    from riann_ros.nodes.node_base import EstimatorNode

    mod = importlib.import_module(f"riann_ros.nodes.{name}_node")
    for obj in vars(mod).values():
        if isinstance(obj, type) and issubclass(obj, EstimatorNode) and obj.ESTIMATOR == name:
            return obj.ATTITUDE_TOPIC, obj.IMU_TOPIC
    return "imu/attitude", "imu/data"


def call_service(client: Any, request: Any, timeout: float, resend_every: float = 2.0) -> Any | None:
    """Call a service and wait up to ``timeout`` s for the answer; None when none came.

    The request is sent again every ``resend_every`` s: with Fast DDS, ``wait_for_service`` can return
    before the server has matched the client's response reader, and the first answer is then lost (seen
    once in a few hundred CI runs). Use it for idempotent requests only (``~/reset``, ``~/restart``,
    set_parameters).
    """
    futures = [client.call_async(request)]
    end = time.monotonic() + timeout
    next_send = time.monotonic() + resend_every
    try:
        while time.monotonic() < end:
            for f in futures:
                if f.done():
                    return f.result()
            if time.monotonic() >= next_send:
                futures.append(client.call_async(request))
                next_send += resend_every
            time.sleep(0.002)
        return None
    finally:
        for f in futures:
            if not f.done():
                client.remove_pending_request(f)


def node_executable(name: str) -> str:
    exe = Path(sys.executable).parent / f"{name}_node"
    if exe.exists():
        return str(exe)
    found = shutil.which(f"{name}_node")
    if found is None:
        raise EvalError(f"--live: {name}_node is not installed (run make setup)")
    return found


class LiveRunner:
    """Replays scenario sequences over DDS to one node per estimator and collects what they publish.

    Without ``topics`` the runner starts ``<name>_node`` per spec (input remapped to
    ``/riann_eval/imu/data_raw``, output to ``/riann_eval/e<i>/attitude``, reliable QoS) with the
    sequence's rate as ``nominal_rate``; with ``topics`` they name the attitude topics of nodes already
    running on ``input_topic``. Before each replay the started nodes' ``~/restart`` is called, so every
    replay starts the estimators as freshly built, as offline (``~/reset`` would keep the robot's magnetometer
    calibration and latency fit from the replays before); replays are also separated by a stamp gap larger
    than the nodes' ``max_dt`` (all that separates them for external nodes). With a magnetometer in the sequence
    (and ``use_mag`` not ``false``, passed to the started nodes), the field paired with each sample is published on
    ``/riann_eval/imu/mag`` at the sample's stamp (NaN where none is fresh), so the started nodes pair each sample
    with the field the offline run gives it. Publishing is paced at ``speed``
    × real time (0: as fast as the slowest node keeps up) with at most ``window`` samples in flight.
    One replay at a time: a pass over the input per scenario (``interleaved = False``).
    """

    mode = "live"
    interleaved = False

    def __init__(self, speed: float = 1.0, window: int = 200, input_topic: str | None = None,
                 topics: list[str] | None = None, log_dir: Path | None = None, use_mag: str = "auto") -> None:
        import rclpy
        from geometry_msgs.msg import QuaternionStamped
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import Imu, MagneticField

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
        self.pub = self.node.create_publisher(Imu, self.input_topic, self._qos)
        self.use_mag = use_mag
        self._Mag = MagneticField
        # the field for the started nodes (external ones subscribe to a magnetometer topic of their own)
        self.mag_pub = (self.node.create_publisher(MagneticField, LIVE_MAG_TOPIC, self._qos)
                        if topics is None and use_mag != "false" else None)
        self._exec = SingleThreadedExecutor(context=self._ctx)
        self._exec.add_node(self.node)
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()
        self._procs: list[subprocess.Popen] = []
        self._subs: list[Any] = []
        self.got: list[list[Output]] = []  # per estimator, outputs received and not yet collected
        self.next_stamp = 1_000_000_000
        self._started_for: tuple | None = None
        self.reads_mag: list[bool] = []  # per started node: it reads the published field (its estimator uses one)

    def _spin(self) -> None:
        with contextlib.suppress(Exception):
            while self._ctx.ok():
                self._exec.spin_once(timeout_sec=0.05)

    def __enter__(self) -> LiveRunner:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- nodes ----------------------------------------------------------------------------------
    def _subscribe(self, topics: list[str], imu: bool = False) -> None:
        """Collect each topic's outputs: ``imu`` ones are the nodes' ``sensor_msgs/Imu`` output, whose orientation
        covariance gives the σ (:func:`~riann_ros.bagio.topics.sigmas_of_variances`, as for a recorded topic);
        otherwise ``QuaternionStamped`` attitude topics (no σ)."""
        for s in self._subs:
            self.node.destroy_subscription(s)
        self._subs, self.got = [], []
        for topic in topics:
            box: list[Output] = []
            self.got.append(box)

            def on_quat(m: Any, box: list[Output] = box) -> None:
                q = m.quaternion
                box.append((stamps.to_ns(m.header.stamp), q.w, q.x, q.y, q.z, *NO_VARIANCES))

            def on_imu(m: Any, box: list[Output] = box) -> None:
                q, c = m.orientation, m.orientation_covariance
                box.append((stamps.to_ns(m.header.stamp), q.w, q.x, q.y, q.z, c[0], c[4], c[8]))

            kind, cb = (self._Imu, on_imu) if imu else (self._Quat, on_quat)
            self._subs.append(self.node.create_subscription(kind, topic, cb, self._qos))

    def _node_command(self, i: int, spec: EstimatorSpec, rate: float) -> list[str]:
        att_topic, imu_topic = node_topics(spec.name)
        remaps = {"__node": f"riann_eval_{i}_{spec.name}", "imu/data_raw": self.input_topic,
                  "imu/mag": LIVE_MAG_TOPIC, att_topic: f"{LIVE_NS}/e{i}/attitude", imu_topic: f"{LIVE_NS}/e{i}/imu"}
        params = {"input_qos": "reliable", "input_depth": 1000, "output_depth": 1000, "nominal_rate": float(rate),
                  "use_mag": self.use_mag, **spec.node_params}
        return [node_executable(spec.name), "--ros-args",
                *(a for k, v in remaps.items() for a in ("-r", f"{k}:={v}")),
                *(a for k, v in params.items() for a in ("-p", f"{k}:={ros_param(v)}"))]

    def _ensure_nodes(self, specs: list[EstimatorSpec], rate: float) -> None:
        key = (tuple(specs), round(rate, 6))
        if self._started_for == key:
            return
        if self.external is not None:
            if len(self.external) != len(specs):
                raise EvalError(f"--live-topics gives {len(self.external)} topics for {len(specs)} estimators")
            if self._started_for is None:
                self.reads_mag = [False] * len(specs)
                self._subscribe(self.external)
                self._wait_connected()
            self._started_for = key
            return
        self.stop_nodes()
        for i, spec in enumerate(specs):
            with open(self.log_dir / f"node_{i}_{spec.name}.log", "w") as log:  # the child keeps its own fd
                self._procs.append(subprocess.Popen(self._node_command(i, spec, rate), stdout=log,
                                                    stderr=subprocess.STDOUT))
        self._subscribe([f"{LIVE_NS}/e{i}/imu" for i in range(len(specs))], imu=True)
        self.reads_mag = [self.mag_pub is not None and estimator_class(spec.name).USES_MAG for spec in specs]
        self._wait_connected(sum(self.reads_mag))
        self._started_for = key

    def _wait_connected(self, mag_readers: int = 0, timeout: float = 60.0) -> None:
        """Until every node reads the input (and ``mag_readers`` of them the field) and publishes its output."""
        end = time.monotonic() + timeout
        n = len(self._subs)
        mag_pub = self.mag_pub
        while time.monotonic() < end:
            if (self.pub.get_subscription_count() >= n
                    and (mag_pub is None or mag_pub.get_subscription_count() >= mag_readers)
                    and all(s.get_publisher_count() > 0 for s in self._subs)):
                time.sleep(0.3)  # let discovery settle in both directions
                return
            if any(p.poll() is not None for p in self._procs):
                break
            time.sleep(0.05)
        logs = "; ".join(f"{p.name}: {p.read_text()[-300:]}" for p in sorted(self.log_dir.glob("node_*.log")))
        raise EvalError(f"--live: the estimator nodes did not connect ({logs or 'no logs'})")

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

    # -- runs -----------------------------------------------------------------------------------
    def _restart_nodes(self, specs: list[EstimatorSpec], timeout: float = 10.0) -> None:
        """Call every started node's ``~/restart``: each replay starts its estimator as freshly built, as the
        offline run does (a stamp gap alone would not: RIANN keeps its gyro-bias estimate across gaps; nor would
        ``~/reset``: it keeps the robot's magnetometer calibration and latency fit)."""
        from std_srvs.srv import Trigger

        for i, spec in enumerate(specs):
            client = self.node.create_client(Trigger, f"/riann_eval_{i}_{spec.name}/restart")
            try:
                if not client.wait_for_service(timeout_sec=timeout):
                    raise EvalError(f"--live: {spec.name}_node offers no ~/restart service")
                if call_service(client, Trigger.Request(), timeout) is None:
                    raise EvalError(f"--live: {spec.name}_node did not answer ~/restart")
            finally:
                self.node.destroy_client(client)

    def start(self, specs: list[EstimatorSpec], gate: GateConfig) -> _LiveRun:
        self._ensure_nodes(specs, gate.nominal_rate)
        if self.external is None:
            self._restart_nodes(specs)
        for box in self.got:
            box.clear()
        return _LiveRun(self)


class _LiveRun:
    """One replay: pieces are published in turn, each returns once the nodes answered its last sample."""

    def __init__(self, runner: LiveRunner) -> None:
        self.r = runner
        self.offset: int | None = None  # added to the sequence's stamps: the replay starts at runner.next_stamp
        self.t0 = 0.0
        self.first_ns = self.last_ns = runner.next_stamp
        self.published = 0
        self.mag_samples = 0  # samples published with a field (what offline's RunStats.mag_samples counts)
        self.received = [0] * len(runner.got)
        self.unexpected = [0] * len(runner.got)
        self.sigmas: list[NDArray[np.float64] | None] = []  # of the last feed, per estimator (N, 2)

    def _publish(self, st: NDArray[np.int64], rec: Recording) -> None:
        r = self.r
        msg = r._Imu()
        msg.header.frame_id = rec.frame_id
        msg.orientation_covariance[0] = -1.0
        la, av = msg.linear_acceleration, msg.angular_velocity
        rel = (st - self.first_ns) * 1e-9
        fields = self._fields(st, rec)
        for i, (s, a, g) in enumerate(zip(st.tolist(), rec.acc.tolist(), rec.gyr.tolist(), strict=True)):
            if fields is not None:
                fields(i)
            if r.speed > 0:
                delay = self.t0 + rel[i] / r.speed - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
            stall_end = time.monotonic() + 2.0  # the outputs of this piece collect in r.got
            while i - min(len(b) for b in r.got) >= r.window and time.monotonic() < stall_end:
                time.sleep(0.0002)
            stamps.set_ns(msg.header.stamp, s)
            la.x, la.y, la.z = a
            av.x, av.y, av.z = g
            r.pub.publish(msg)
        self.published += len(st)

    def _fields(self, st: NDArray[np.int64], rec: Recording) -> Callable[[int], None] | None:
        """Publishes the fields up to ``MAG_LEAD`` samples ahead of sample i, each at its sample's stamp (None: no
        field to publish)."""
        pub = self.r.mag_pub
        if pub is None or rec.mag is None:
            return None
        msg = self.r._Mag()
        msg.header.frame_id = rec.frame_id
        mf = msg.magnetic_field
        stamp_list, field_list = st.tolist(), rec.mag.tolist()
        done = 0

        def publish_to(i: int) -> None:
            nonlocal done
            for j in range(done, min(i + MAG_LEAD + 1, len(stamp_list))):
                stamps.set_ns(msg.header.stamp, stamp_list[j])
                mf.x, mf.y, mf.z = field_list[j]
                self.mag_samples += all(map(math.isfinite, field_list[j]))
                pub.publish(msg)
            done = max(done, i + MAG_LEAD + 1)

        return publish_to

    def _wait(self, last: int) -> None:
        got = self.r.got
        idle_end = time.monotonic() + IDLE_S
        counts = [len(b) for b in got]
        while time.monotonic() < idle_end:
            if all(b and b[-1][0] >= last for b in got):
                return
            time.sleep(0.01)
            now = [len(b) for b in got]
            if now != counts:
                counts, idle_end = now, time.monotonic() + IDLE_S

    def feed(self, rec: Recording) -> list[NDArray[np.float64]]:
        if self.offset is None:
            self.offset = self.r.next_stamp - int(rec.stamps_ns[0])
            self.t0 = time.monotonic()
        st = rec.stamps_ns + self.offset
        self._publish(st, rec)
        self.last_ns = int(st[-1])
        self._wait(self.last_ns)
        index = {s: k for k, s in enumerate(st.tolist())}
        out = []
        self.sigmas = []
        for j, box in enumerate(self.r.got):
            qs = np.full((len(st), 7), np.nan)
            outputs, box[:] = list(box), []
            for o in outputs:
                k = index.get(int(o[0]))
                if k is None:
                    self.unexpected[j] += 1
                else:
                    qs[k] = o[1:]
            self.received[j] += int(np.isfinite(qs[:, :4]).all(axis=1).sum())
            out.append(qs[:, :4])
            sig = sigmas_of_variances(qs[:, 4:])
            self.sigmas.append(sig if np.isfinite(sig[:, 0]).any() else None)
        return out

    def finish(self) -> list[RunStats]:
        self.r.next_stamp = self.last_ns + LIVE_GAP_NS
        wall = time.monotonic() - self.t0
        n = self.published
        return [
            RunStats(seconds=wall, live={"published": n, "received": rec, "lost": n - rec, "unexpected": unexp},
                     mag_samples=self.mag_samples if reads else 0)
            for rec, unexp, reads in zip(self.received, self.unexpected, self.r.reads_mag, strict=True)
        ]
