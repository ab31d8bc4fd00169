"""``riann-topic``: see what the nodes publish without a ROS installation (``ros2 topic list / echo / hz``).

Example::

    riann-topic list
    riann-topic echo imu/attitude --count 3
    riann-topic echo /diagnostics
    riann-topic hz imu/attitude --duration 10

It runs one rclpy node of its own in the DDS domain of the environment (``ROS_DOMAIN_ID``,
``ROS_AUTOMATIC_DISCOVERY_RANGE``), finds a topic's type from the graph and imports its message class
(any type installed in this Python: ``QuaternionStamped``, ``Imu``, ``Vector3Stamped``,
``DiagnosticArray``, ``MagneticField``, …). ``echo`` prints each message as YAML, like ``ros2 topic echo``;
``hz`` prints the receive rate every second, like ``ros2 topic hz``, and for stamped messages the rate of
their header stamps. Exit status: 0 ok, 1 no such topic / type / no message in time, 2 bad command line,
130 interrupted. ROS glue only: nothing in the core imports it.
"""

from __future__ import annotations

import argparse
import importlib
import math
import os
import statistics
import sys
import time
from collections import deque
from typing import Any

import yaml

QOS_CHOICES = ("auto", "reliable", "best_effort")
GIVEN_WAIT_S = 2.0  # with --type: how long to look for the topic in the graph before subscribing anyway


class TopicError(Exception):
    """A topic, type or message that is not there; the text says which."""


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="riann-topic",
        description="List topics, print their messages (echo) or their rate (hz), over DDS, without a ROS "
        "installation; the nodes' topics: imu/attitude, imu/data, imu/rpy, imu/<name>/..., /diagnostics.",
        epilog="environment: ROS_DOMAIN_ID and ROS_AUTOMATIC_DISCOVERY_RANGE as for the nodes.\n"
        "exit status: 0 ok, 1 no such topic or type or no message in time, 2 usage error, 130 interrupted",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = p.add_subparsers(dest="verb", required=True)
    lst = sub.add_parser("list", help="topics and their types")
    lst.add_argument("--wait", type=float, default=2.0, metavar="S", help="discovery time before listing (2 s)")
    for verb, text in (("echo", "print each message as YAML"), ("hz", "print the message rate every second")):
        s = sub.add_parser(verb, help=text)
        s.add_argument("topic", help="topic name; relative names are taken from the root namespace")
        s.add_argument("--type", default=None, metavar="TYPE",
                       help="message type (pkg/msg/Name) when the topic has no publisher yet; default: from the graph")
        s.add_argument("--qos", choices=QOS_CHOICES, default="auto",
                       help="reliability of the subscription; auto: best effort if any publisher is best effort")
        s.add_argument("--timeout", type=float, default=10.0, metavar="S",
                       help="give up when the topic has not appeared, or no message came, after this long (10 s)")
        if verb == "echo":
            s.add_argument("-n", "--count", type=int, default=0, metavar="N", help="exit after N messages")
        else:
            s.add_argument("--duration", type=float, default=0.0, metavar="S", help="exit after S seconds")
            s.add_argument("--window", type=int, default=10000, metavar="N", help="messages per statistic (10000)")
    return p


def message_class(type_name: str) -> Any:
    """The message class of ``pkg/msg/Name`` (or ``pkg/Name``)."""
    parts = type_name.split("/")
    if len(parts) not in (2, 3):
        raise TopicError(f"message type must be pkg/msg/Name, got {type_name!r}")
    pkg, name = parts[0], parts[-1]
    try:
        return getattr(importlib.import_module(f"{pkg}.msg"), name)
    except (ImportError, AttributeError):
        raise TopicError(f"message type {type_name} is not installed in this Python") from None


def plain(value: Any) -> Any:
    """A message as nested dicts, lists and scalars (what ``ros2 topic echo`` prints)."""
    if hasattr(value, "get_fields_and_field_types"):
        return {f: plain(getattr(value, f)) for f in value.get_fields_and_field_types()}
    if isinstance(value, bytes):
        return value[0] if len(value) == 1 else list(value)
    if isinstance(value, str | bool | int | float) or value is None:
        return value
    if hasattr(value, "tolist"):  # numpy arrays, array.array
        return [plain(v) for v in value.tolist()]
    if isinstance(value, list | tuple):
        return [plain(v) for v in value]
    return str(value)


def to_yaml(msg: Any) -> str:
    return yaml.safe_dump(plain(msg), sort_keys=False, default_flow_style=False, allow_unicode=True)


def header_stamp(msg: Any) -> float | None:
    """The header stamp in seconds, None without a header (or an unstamped message)."""
    h = getattr(msg, "header", None)
    if h is None:
        return None
    s = h.stamp.sec + h.stamp.nanosec * 1e-9
    return s if s > 0.0 else None


class RateStats:
    """Rate of arrivals (and of header stamps) over a sliding window, as ``ros2 topic hz`` reports it."""

    def __init__(self, window: int) -> None:
        self.arrivals: deque[float] = deque(maxlen=window + 1)
        self.stamps: deque[float] = deque(maxlen=window + 1)
        self.total = 0

    def add(self, arrival_s: float, stamp_s: float | None) -> None:
        self.arrivals.append(arrival_s)
        if stamp_s is not None:
            self.stamps.append(stamp_s)
        self.total += 1

    @staticmethod
    def _line(times: deque[float], what: str) -> str | None:
        dts = [b - a for a, b in zip(times, list(times)[1:], strict=False)]
        if not dts or sum(dts) <= 0.0:
            return None
        mean = sum(dts) / len(dts)
        std = statistics.pstdev(dts) if len(dts) > 1 else 0.0
        return (f"{what}: {1.0 / mean:.3f} Hz  min {min(dts):.6f} s  max {max(dts):.6f} s  std dev {std:.6f} s  "
                f"window {len(dts) + 1}")

    def report(self) -> list[str]:
        lines = [self._line(self.arrivals, "average rate"), self._line(self.stamps, "header stamps")]
        return [line for line in lines if line is not None]


class TopicTool:
    """One rclpy node in its own context, spun in the calling thread."""

    def __init__(self) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node(f"riann_topic_{os.getpid()}", context=self.context,
                                      start_parameter_services=False)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self.context.try_shutdown()

    def spin_for(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end and self.context.ok():
            self.executor.spin_once(timeout_sec=max(0.0, min(0.05, end - time.monotonic())))

    def topics(self) -> dict[str, list[str]]:
        return dict(self.node.get_topic_names_and_types())

    def resolve(self, topic: str) -> str:
        return self.node.resolve_topic_name(topic)

    def topic_type(self, topic: str, given: str | None, timeout: float) -> str:
        """The topic's type from the graph (waiting up to ``timeout``), or ``given`` (checked against the graph once
        the topic shows up; taken as it is when it has not shown up within ``GIVEN_WAIT_S``)."""
        start = time.monotonic()
        while True:
            types = self.topics().get(topic)
            if types and given is not None:
                if given not in types and _short(given) not in map(_short, types):
                    raise TopicError(f"{topic} has type {', '.join(types)}, not {given}")
                return given
            if types:
                if len(types) > 1:
                    raise TopicError(f"{topic} has several types ({', '.join(types)}): choose one with --type")
                return types[0]
            waited = time.monotonic() - start
            if given is not None and waited >= min(timeout, GIVEN_WAIT_S):
                return given
            if waited >= timeout:
                raise TopicError(f"no topic {topic} after {timeout:g} s ({_domain_text()}); riann-topic list shows "
                                 "what there is")
            self.spin_for(0.1)

    def no_message(self, topic: str, type_name: str, timeout: float) -> TopicError:
        """The error when nothing came: a type the topic's publishers have (they may have shown up only after the
        subscription, on a slow discovery; the graph's type list would include this reader's own type) is named,
        else that no message came."""
        types = sorted({i.topic_type for i in self.node.get_publishers_info_by_topic(topic)})  # not our own reader
        if types and type_name not in types and _short(type_name) not in map(_short, types):
            return TopicError(f"{topic} has type {', '.join(types)}, not {type_name}")
        return TopicError(f"no message on {topic} ({type_name}) in {timeout:g} s")

    def qos(self, topic: str, kind: str) -> Any:
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

        if kind == "auto":
            infos = self.node.get_publishers_info_by_topic(topic)
            best_effort = any(i.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT for i in infos)
            kind = "best_effort" if best_effort else "reliable"
        reliability = ReliabilityPolicy.RELIABLE if kind == "reliable" else ReliabilityPolicy.BEST_EFFORT
        return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=reliability,
                          durability=DurabilityPolicy.VOLATILE)

    def subscribe(self, topic: str, type_name: str, qos_kind: str, callback: Any) -> None:
        self.node.create_subscription(message_class(type_name), topic, callback, self.qos(topic, qos_kind))


def _short(type_name: str) -> str:
    return type_name.split("/")[-1]


def _domain_text() -> str:
    return (f"ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID', '0 (unset)')}, ROS_AUTOMATIC_DISCOVERY_RANGE="
            f"{os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE', '(unset)')}")


def cmd_list(tool: TopicTool, args: argparse.Namespace) -> int:
    tool.spin_for(args.wait)
    for name, types in sorted(tool.topics().items()):
        print(f"{name} [{', '.join(types)}]")
    return 0


def cmd_echo(tool: TopicTool, args: argparse.Namespace) -> int:
    topic = tool.resolve(args.topic)
    type_name = tool.topic_type(topic, args.type, args.timeout)
    received: list[Any] = []

    def on_msg(msg: Any) -> None:
        if args.count and len(received) >= args.count:
            return
        received.append(msg)
        sys.stdout.write(to_yaml(msg) + "---\n")
        sys.stdout.flush()

    tool.subscribe(topic, type_name, args.qos, on_msg)
    start = time.monotonic()
    while not args.count or len(received) < args.count:
        tool.spin_for(0.1)
        if not received and time.monotonic() - start > args.timeout:
            raise tool.no_message(topic, type_name, args.timeout)
    return 0


def cmd_hz(tool: TopicTool, args: argparse.Namespace) -> int:
    topic = tool.resolve(args.topic)
    type_name = tool.topic_type(topic, args.type, args.timeout)
    stats = RateStats(args.window)
    tool.subscribe(topic, type_name, args.qos, lambda msg: stats.add(time.monotonic(), header_stamp(msg)))
    start = time.monotonic()
    print(f"subscribed to {topic} [{type_name}]", flush=True)
    while not args.duration or time.monotonic() - start < args.duration:
        tool.spin_for(1.0)
        if stats.total == 0 and time.monotonic() - start > args.timeout:
            raise tool.no_message(topic, type_name, args.timeout)
        for line in stats.report():
            print(line, flush=True)
    print(f"{stats.total} messages in {time.monotonic() - start:.1f} s", flush=True)
    return 0


VERBS = {"list": cmd_list, "echo": cmd_echo, "hz": cmd_hz}


def keep_stdout_clean() -> None:
    """Send what the DDS libraries print on file descriptor 1 (Fast DDS' coloured log lines on a busy machine) to
    stderr, so that stdout holds only riann-topic's own output (YAML documents for ``echo``, a pipe stays parseable)."""
    sys.stdout.flush()
    ours = os.dup(1)
    os.dup2(2, 1)
    sys.stdout = os.fdopen(ours, "w", buffering=1)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.verb != "list" and not math.isfinite(args.timeout):
        print("riann-topic: error: --timeout must be finite", file=sys.stderr)
        return 2
    keep_stdout_clean()
    tool = TopicTool()
    try:
        return VERBS[args.verb](tool, args)
    except TopicError as e:
        print(f"riann-topic: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
    finally:
        tool.close()


if __name__ == "__main__":
    raise SystemExit(main())
