"""``riann-topic``: see what the nodes publish without a ROS installation (``ros2 topic list / echo / hz``).

Example::

    riann-topic list
    riann-topic echo imu/attitude --count 3
    riann-topic echo /diagnostics
    riann-topic hz imu/attitude --duration 10

It runs one rclpy node of its own (the ROS layer's :class:`riann_ros.ros.topics.TopicTool`) in the DDS domain of
the environment (``ROS_DOMAIN_ID``, ``ROS_AUTOMATIC_DISCOVERY_RANGE``), finds a topic's type from the graph and
imports its message class (any type installed in this Python: ``QuaternionStamped``, ``Imu``, ``Vector3Stamped``,
``DiagnosticArray``, ``MagneticField``, …). ``echo`` prints each message as YAML, like ``ros2 topic echo``;
``hz`` prints the receive rate every second, like ``ros2 topic hz``, and for stamped messages the rate of
their header stamps. Exit status: 0 ok, 1 no such topic / type / no message in time, 2 bad command line,
130 interrupted. This module is the command (its options, what it prints); it imports the ROS layer when it runs.
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
import time
from collections import deque
from typing import TYPE_CHECKING, Any

import yaml

if TYPE_CHECKING:
    from riann_ros.ros.topics import TopicTool

QOS_CHOICES = ("auto", "reliable", "best_effort")


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
    from riann_ros.ros.topics import TopicError, TopicTool

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
