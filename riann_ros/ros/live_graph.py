"""What the DDS graph says about a ``riann-bag-eval --live`` replay's topics (rclpy): which of them have no node on
the other side yet (:func:`missing`), and which have publishers besides the ones the replay expects
(:func:`crowded`), each as one line naming the topic and the nodes."""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Wanted:
    """A topic of the replay and what it needs on the other side: ``readers`` subscribers to a topic it publishes
    (``publishes``), else a publisher of a topic it listens to; ``what``: the topic's role, for a message."""

    topic: str
    what: str
    publishes: bool
    readers: int = 1


def domain_text() -> str:
    """The DDS settings that decide which nodes this process sees, for a message."""
    return (f"ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID', '0 (unset)')}, ROS_AUTOMATIC_DISCOVERY_RANGE="
            f"{os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE', '(unset)')}")


def missing(node: Any, wanted: Sequence[Wanted]) -> list[str]:
    """Each wanted topic without its other side yet (as seen from ``node``), as a phrase naming it."""
    out = []
    for w in wanted:
        if w.publishes:
            have = node.count_subscribers(w.topic)
            if have < w.readers:
                out.append(f"no node subscribes to {w.topic} ({w.what})" if not have else
                           f"{have} of {w.readers} nodes subscribe to {w.topic} ({w.what})")
        elif not node.count_publishers(w.topic):
            out.append(f"no node publishes {w.topic} ({w.what})")
    return out


def crowded(node: Any, wanted: Sequence[Wanted], own: str) -> list[str]:
    """Each wanted topic with more publishers than the replay expects — on a topic it publishes, any node but
    ``own`` (this replay's node name); on one it listens to, more than one node — as a warning naming them: their
    messages mix with the replay's (the nodes get two streams, the scores count the difference as lost)."""
    out = []
    for w in wanted:
        names = [_full_name(i) for i in node.get_publishers_info_by_topic(w.topic)]
        nodes = ", ".join(sorted(set(names) - {own}))
        if w.publishes and any(n != own for n in names):
            out.append(f"{w.topic} ({w.what}) has another publisher besides this run: {nodes}; its messages mix with "
                       "the replay's (stop it, or use other topics or another ROS_DOMAIN_ID)")
        elif not w.publishes and len(names) > 1:
            out.append(f"{w.topic} ({w.what}) has {len(names)} publishers where one is expected: {nodes}; their "
                       "messages mix (stop the others, or use other topics or another ROS_DOMAIN_ID)")
    return out


def _full_name(info: Any) -> str:
    ns = info.node_namespace.rstrip("/")
    return f"{ns}/{info.node_name}"
