"""A replay of recordings to the estimator nodes over DDS: what it takes and gives (ROS-free).

The ROS side (:class:`riann_ros.ros.dds_replay.DdsReplay`, rclpy) starts one node per :class:`NodeSpec`, publishes
each piece of a sequence as IMU messages (and the paired magnetic field) and collects what the nodes publish at the
piece's samples; the evaluator's side (:class:`riann_ros.evaluation.live.LiveRunner`, ``riann-bag-eval --live``)
turns that into estimates, σ and run statistics. Both meet here, in the :class:`Replay` protocol and its records,
so neither imports the other.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from riann_ros.recording import Recording


class ReplayError(Exception):
    """The replay cannot go on (a node not installed, not connecting, not answering); the text says which."""


@dataclass(frozen=True)
class NodeSpec:
    """One estimator node of a replay: ``<name>_node`` with these parameters (``-p name:=value``, beside the
    replay's own), and whether its estimator reads the magnetic field."""

    name: str
    params: tuple[tuple[str, Any], ...] = ()
    uses_mag: bool = False


@dataclass
class PieceOutputs:
    """What the nodes published for one piece of a sequence, per node in the order of the specs."""

    # (N, 7) per node at the piece's N samples: quaternion w, x, y, z and the orientation variances about x, y, z
    # (rad²; NaN where the topic carries none); a row of NaN where the node published nothing for that sample
    rows: list[NDArray[np.float64]]
    unexpected: list[int]  # outputs at a stamp that is none of the piece's samples


@dataclass
class SequenceCounts:
    """One sequence's replay as a whole."""

    published: int  # IMU messages published
    mag_samples: int  # of them, samples published with a finite field
    wall_s: float  # from the first piece's start to the end
    reads_mag: list[bool]  # per node: it read the published field


class ReplaySequence(Protocol):
    """One sequence being replayed: its pieces are sent in order, each returning once the nodes answered it."""

    def send(self, rec: Recording) -> PieceOutputs: ...

    def end(self) -> SequenceCounts: ...


class Replay(Protocol):
    """The nodes and the DDS connection to them, for sequence after sequence (ReplayError when it cannot go on)."""

    def sequence(self, nodes: Sequence[NodeSpec], rate: float) -> ReplaySequence:
        """A new sequence at ``rate`` Hz (the nodes' ``nominal_rate``), each node's estimator as freshly built."""
        ...

    def close(self) -> None: ...
