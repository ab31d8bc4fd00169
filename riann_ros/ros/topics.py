"""``riann-topic``'s reader of the DDS graph (rclpy): one node of its own that lists the topics, finds a topic's type
and subscribes to it with the message class of that type. The command (options, printing) is
:mod:`riann_ros.cli.topic`."""

from __future__ import annotations

import importlib
import os
import time
from typing import Any

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from riann_ros.ros.live_graph import domain_text

GIVEN_WAIT_S = 2.0  # with a type given: how long to look for the topic in the graph before subscribing anyway


class TopicError(Exception):
    """A topic, type or message that is not there; the text says which."""


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


class TopicTool:
    """One rclpy node in its own context, spun in the calling thread."""

    def __init__(self) -> None:
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
                raise TopicError(f"no topic {topic} after {timeout:g} s ({domain_text()}); riann-topic list shows "
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

