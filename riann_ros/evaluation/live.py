"""The evaluator's side of ``riann-bag-eval --live`` (ROS-free): a :class:`~riann_ros.evaluation.runners.Runner` whose
estimates come from the estimator nodes over DDS.

:class:`LiveRunner` drives a :class:`riann_ros.replay.Replay` — :class:`riann_ros.ros.dds_replay.DdsReplay` in the
ROS layer, which the command line gives it — one sequence per run, and turns what the nodes published into the
pipeline's estimates, σ (from the covariance of their ``sensor_msgs/Imu`` output, as for a recorded topic) and
:class:`~riann_ros.evaluation.results.RunStats` (messages published, received, lost), so the same scoring applies.
A replay that cannot go on (the nodes' topics not connected) stops the whole run
(:class:`~riann_ros.evaluation.errors.RunStopped`): every input would fail the same way.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from riann_ros.bagio.topics import sigmas_of_variances
from riann_ros.estimators import estimator_class
from riann_ros.evaluation.errors import RunStopped
from riann_ros.evaluation.results import RunStats
from riann_ros.evaluation.specs import EstimatorSpec
from riann_ros.gate import GateConfig
from riann_ros.recording import Recording
from riann_ros.replay import NodeSpec, Replay, ReplayError, ReplaySequence


class LiveRunner:
    """Each run replays its sequence to one node per estimator (``replay``, closed with the runner). One replay at a
    time: a pass over the input per scenario (``interleaved = False``); an object of this process (its DDS
    participant and nodes), so its inputs are evaluated in this process
    (:class:`~riann_ros.evaluation.executors.ExecutorSetting`). ``note`` gets a line as each replay (an input in
    one scenario and condition) starts and ends, with its time: a replay takes the recording's length at
    ``--speed 1``."""

    mode = "live"
    interleaved = False

    def __init__(self, replay: Replay, note: Callable[[str], None] | None = None) -> None:
        self.replay = replay
        self.note = note or (lambda _: None)

    def __enter__(self) -> LiveRunner:
        return self

    def __exit__(self, *exc: object) -> None:
        self.replay.close()

    def start(self, specs: list[EstimatorSpec], gate: GateConfig, what: str = "") -> _LiveRun:
        nodes = [NodeSpec(s.name, tuple(s.node_params.items()), estimator_class(s.name).USES_MAG) for s in specs]
        started = time.monotonic()
        try:
            sequence = self.replay.sequence(nodes, gate.nominal_rate)
        except ReplayError as exc:
            raise RunStopped(f"--live: {exc}") from exc
        self.note(f"live: {what}: replaying to {len(specs)} node(s)")
        return _LiveRun(sequence, len(specs), lambda text: self.note(
            f"live: {what}: {text} in {time.monotonic() - started:.1f} s"))


class _LiveRun:
    """One replay: each piece's outputs as estimates and σ, the counts as run statistics."""

    def __init__(self, sequence: ReplaySequence, n: int, done: Callable[[str], None]) -> None:
        self.sequence = sequence
        self.done = done  # told what the replay gave when it ends
        self.received = [0] * n
        self.unexpected = [0] * n
        self.sigmas: list[NDArray[np.float64] | None] = []  # of the last feed, per estimator (N, 2)

    def feed(self, rec: Recording) -> list[NDArray[np.float64]]:
        got = self.sequence.send(rec)
        out = []
        self.sigmas = []
        for j, (rows, unexpected) in enumerate(zip(got.rows, got.unexpected, strict=True)):
            self.unexpected[j] += unexpected
            self.received[j] += int(np.isfinite(rows[:, :4]).all(axis=1).sum())
            out.append(rows[:, :4])
            sig = sigmas_of_variances(rows[:, 4:])
            self.sigmas.append(sig if np.isfinite(sig[:, 0]).any() else None)
        return out

    def finish(self) -> list[RunStats]:
        counts = self.sequence.end()
        n = counts.published
        self.done(f"{n} samples published, received {', '.join(map(str, self.received))}")
        return [
            RunStats(seconds=counts.wall_s, live={"published": n, "received": rec, "lost": n - rec,
                                                  "unexpected": unexp},
                     mag_samples=counts.mag_samples if reads else 0)
            for rec, unexp, reads in zip(self.received, self.unexpected, counts.reads_mag, strict=True)
        ]
