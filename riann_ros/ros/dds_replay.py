"""A replay of recordings over DDS to the estimator nodes (rclpy): the ROS side of ``riann-bag-eval --live``.

:class:`DdsReplay` implements :class:`riann_ros.replay.Replay`: it publishes each piece of a sequence as
``sensor_msgs/Imu`` (and the paired field as ``sensor_msgs/MagneticField``) and collects what the nodes publish, by
stamp, into :class:`~riann_ros.replay.PieceOutputs`; the evaluator's runner
(:class:`riann_ros.evaluation.live.LiveRunner`) turns those into estimates and scores.
"""

from __future__ import annotations

import contextlib
import math
import os
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import rclpy
from geometry_msgs.msg import QuaternionStamped
from numpy.typing import NDArray
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu, MagneticField

from riann_ros import stamps
from riann_ros.magcal.input import UseMag
from riann_ros.recording import Recording
from riann_ros.replay import NodeSpec, PieceOutputs, ReplayError, SequenceCounts
from riann_ros.ros.live_graph import Wanted, crowded, domain_text, missing
from riann_ros.ros.started_nodes import LIVE_INPUT_TOPIC, LIVE_MAG_TOPIC, StartedNodes, output_topic

LIVE_GAP_NS = 2_000_000_000  # stamp gap between sequences (> the nodes' max_dt), besides the ~/restart call
IDLE_S = 5.0  # give up waiting for outputs after this long without a new one
MAG_LEAD = 2  # a sample's field is published this many IMU messages ahead of it (there when its IMU message is)
START_S = 60.0  # nodes the replay started: how long their start (RIANN loads its network) and discovery may take
CONNECT_S = 6.0  # nodes already running (--live-topics): how long their topics may take to show up

# stamp_ns, w, x, y, z and the orientation variances about x, y, z (rad²; NaN: the topic carries no covariance)
Output = tuple[float, ...]
NO_VARIANCES = (math.nan, math.nan, math.nan)


class DdsReplay:
    """Replays sequences over DDS to one node per spec and collects what they publish.

    Without ``topics`` it starts ``<name>_node`` per spec (:mod:`~riann_ros.ros.started_nodes`: input remapped to
    ``/riann_eval/imu/data_raw``, output to ``/riann_eval/e<i>/...``, reliable QoS) with the sequence's rate as
    ``nominal_rate``; with ``topics`` they name the attitude topics of nodes already running on ``input_topic``.
    Before each sequence the started nodes' ``~/restart`` is called, so every sequence starts the estimators as
    freshly built, as offline (``~/reset`` would keep the robot's magnetometer calibration and latency fit from the
    sequences before); sequences are also separated by a stamp gap larger than the nodes' ``max_dt`` (all that
    separates them for external nodes). With a magnetometer in the sequence (and ``use_mag`` not ``false``, passed
    to the started nodes), the field paired with each sample is published as ``sensor_msgs/MagneticField`` on
    ``mag_topic`` (``/riann_eval/imu/mag`` unless given) at the sample's stamp: to the started nodes with NaN where
    none is fresh, so they pair each sample with the field the offline run gives it; to external nodes only the
    finite fields, as a driver publishes them. Publishing is paced at ``speed`` × real time (0: as fast as the
    slowest node keeps up) with at most ``window`` samples in flight. One sequence at a time.

    Before the first sequence the replay waits for a node on the other side of each of its topics: a subscriber of
    the input (and, for started nodes whose estimator uses one, of the field) and a publisher of each output, up to
    :data:`START_S` for nodes it started and :data:`CONNECT_S` for external ones; a topic without one is a
    ReplayError naming it. A topic with publishers besides the expected ones (another node publishing on the input,
    two nodes on an output) is named through ``warn``, once, whenever it is seen (at the connection and at each
    sequence's start and end).
    """

    def __init__(self, speed: float = 1.0, window: int = 200, input_topic: str | None = None,
                 topics: list[str] | None = None, log_dir: Path | None = None, use_mag: str = "auto",
                 mag_topic: str | None = None, warn: Callable[[str], None] | None = None) -> None:
        self.speed = speed
        self.window = window
        self.external = topics
        self.input_topic = input_topic or LIVE_INPUT_TOPIC
        self.mag_topic = mag_topic or LIVE_MAG_TOPIC
        self.use_mag = use_mag
        self.warn = warn or (lambda _: None)
        self._warned: set[str] = set()
        self.nodes = StartedNodes(log_dir or Path(tempfile.mkdtemp(prefix="riann_live_")))
        self._qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        self._ctx = rclpy.context.Context()
        rclpy.init(context=self._ctx)
        self.name = f"riann_bag_eval_live_{os.getpid()}"  # of its own: another run's replay is another node
        self.node = rclpy.create_node(self.name, context=self._ctx)
        try:
            self.pub = self.node.create_publisher(Imu, self.input_topic, self._qos)
            self.mag_pub = (self.node.create_publisher(MagneticField, self.mag_topic, self._qos)
                            if UseMag.parse(use_mag) is not UseMag.FALSE else None)
        except Exception as exc:  # a topic name ROS does not take
            self._ctx.try_shutdown()
            raise ReplayError(f"{exc}".splitlines()[0]) from exc
        self._exec = SingleThreadedExecutor(context=self._ctx)
        self._exec.add_node(self.node)
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()
        self._subs: list[Any] = []
        self.got: list[list[Output]] = []  # per node, outputs received and not yet collected
        self.next_stamp = 1_000_000_000
        self._started_for: tuple | None = None
        self.reads_mag: list[bool] = []  # per node: it reads the published field (its estimator uses one)

    def _spin(self) -> None:
        with contextlib.suppress(Exception):
            while self._ctx.ok():
                self._exec.spin_once(timeout_sec=0.05)

    def close(self) -> None:
        self.nodes.stop()
        with contextlib.suppress(Exception):
            self._ctx.try_shutdown()
        self._thread.join(2)

    def sequence(self, nodes: Sequence[NodeSpec], rate: float) -> _DdsSequence:
        self._ensure_nodes(nodes, rate)
        if self.external is None:
            self.nodes.restart(self.node, nodes)
        self.check_crowded()
        for box in self.got:
            box.clear()
        return _DdsSequence(self)

    def check_crowded(self) -> None:
        """Warn (once each) of the topics with publishers besides the expected ones."""
        for text in crowded(self.node, self._wanted(), f"/{self.name}"):
            if text not in self._warned:
                self._warned.add(text)
                self.warn(text)

    # -- nodes ----------------------------------------------------------------------------------
    def _subscribe(self, topics: list[str], imu: bool = False) -> None:
        """Collect each topic's outputs: ``imu`` ones are the nodes' ``sensor_msgs/Imu`` output, with its orientation
        covariance; otherwise ``QuaternionStamped`` attitude topics (no covariance)."""
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

            kind, cb = (Imu, on_imu) if imu else (QuaternionStamped, on_quat)
            self._subs.append(self.node.create_subscription(kind, topic, cb, self._qos))

    def _ensure_nodes(self, nodes: Sequence[NodeSpec], rate: float) -> None:
        key = (tuple(nodes), round(rate, 6))
        if self._started_for == key:
            return
        if self.external is not None:
            if len(self.external) != len(nodes):
                raise ReplayError(f"{len(self.external)} attitude topics given for {len(nodes)} estimators")
            if self._started_for is None:
                self._subscribe(self.external)
                self._wait_connected(CONNECT_S)
                # the field is read if anything subscribes to it (which node, the graph does not say)
                reads = self.mag_pub is not None and self.mag_pub.get_subscription_count() > 0
                self.reads_mag = [reads] * len(nodes)
            self._started_for = key
            return
        self.nodes.stop()
        self._started_for = None
        self.nodes.start(nodes, rate, self.input_topic, self.use_mag, self.mag_topic)
        self._subscribe([output_topic(i) for i in range(len(nodes))], imu=True)
        self.reads_mag = [self.mag_pub is not None and node.uses_mag for node in nodes]
        self._wait_connected(START_S)
        self._started_for = key

    def _wanted(self) -> list[Wanted]:
        """The replay's topics and the nodes each needs on its other side."""
        external = self.external is not None
        out = [Wanted(self.input_topic, "the IMU input, --live-input", True, 1 if external else len(self._subs))]
        if not external and self.mag_pub is not None and any(self.reads_mag):
            out.append(Wanted(self.mag_topic, "the magnetic field, --live-mag", True, sum(self.reads_mag)))
        elif external and self.mag_pub is not None:
            out.append(Wanted(self.mag_topic, "the magnetic field, --live-mag", True, 0))  # read if a node wants it
        outputs = self.external or [output_topic(i) for i in range(len(self._subs))]
        role = "an estimator's attitude, --live-topics" if external else "a started node's output"
        out += [Wanted(t, role, False) for t in outputs]
        return out

    def _wait_connected(self, timeout: float) -> None:
        """Until each of the replay's topics has its other side (ReplayError naming those that have none by
        ``timeout``, or when a started node ended), then the publishers besides the expected ones warned of."""
        end = time.monotonic() + timeout
        wanted = self._wanted()
        lacking = missing(self.node, wanted)
        while lacking and time.monotonic() < end and not self.nodes.any_ended():
            time.sleep(0.05)
            lacking = missing(self.node, wanted)
        if not lacking:
            time.sleep(0.3)  # let discovery settle in both directions
            self.check_crowded()
            return
        logs = " ".join(self.nodes.logs().split()) if self.external is None else ""
        raise ReplayError(f"{'; '.join(lacking)} after {timeout:g} s ({domain_text()})"
                          + (f"; the started nodes' logs: {logs}" if logs else ""))


class _DdsSequence:
    """One sequence: pieces are published in turn, each returns once the nodes answered its last sample."""

    def __init__(self, replay: DdsReplay) -> None:
        self.r = replay
        self.offset: int | None = None  # added to the sequence's stamps: it starts at replay.next_stamp
        self.t0 = 0.0
        self.first_ns = self.last_ns = replay.next_stamp
        self.published = 0
        self.mag_samples = 0  # samples published with a field

    def _publish(self, st: NDArray[np.int64], rec: Recording) -> None:
        r = self.r
        msg = Imu()
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
        every = self.r.external is None  # the started nodes pair each sample: a NaN field where none is fresh
        msg = MagneticField()
        msg.header.frame_id = rec.frame_id
        mf = msg.magnetic_field
        stamp_list, field_list = st.tolist(), rec.mag.tolist()
        done = 0

        def publish_to(i: int) -> None:
            nonlocal done
            for j in range(done, min(i + MAG_LEAD + 1, len(stamp_list))):
                finite = all(map(math.isfinite, field_list[j]))
                if not (finite or every):
                    continue
                stamps.set_ns(msg.header.stamp, stamp_list[j])
                mf.x, mf.y, mf.z = field_list[j]
                self.mag_samples += finite
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

    def send(self, rec: Recording) -> PieceOutputs:
        if self.offset is None:
            self.offset = self.r.next_stamp - int(rec.stamps_ns[0])
            self.t0 = time.monotonic()
        st = rec.stamps_ns + self.offset
        self._publish(st, rec)
        self.last_ns = int(st[-1])
        self._wait(self.last_ns)
        index = {s: k for k, s in enumerate(st.tolist())}
        out = PieceOutputs(rows=[], unexpected=[])
        for box in self.r.got:
            rows = np.full((len(st), 7), np.nan)
            outputs, box[:] = list(box), []
            unexpected = 0
            for o in outputs:
                k = index.get(int(o[0]))
                if k is None:
                    unexpected += 1
                else:
                    rows[k] = o[1:]
            out.rows.append(rows)
            out.unexpected.append(unexpected)
        return out

    def end(self) -> SequenceCounts:
        self.r.next_stamp = self.last_ns + LIVE_GAP_NS
        self.r.check_crowded()
        return SequenceCounts(published=self.published, mag_samples=self.mag_samples,
                              wall_s=time.monotonic() - self.t0, reads_mag=list(self.r.reads_mag))
