"""What every monitor of the input path is and gives: a level, a verdict, trips and the σ it widens (ROS-free).

A monitor is a physics test of what the stream is fed (the IMU's units, its losses, the magnetometer's readings, its
calibration and timing) that node and evaluator run alike (:class:`~riann_ros.stream.EstimatorStream`). Each gives a
:class:`Verdict`: a level (:class:`Level`, the ``/diagnostics`` level it asks for), a message that names the cause
and the fix, and whether the estimate is then not to be trusted at all (:attr:`Verdict.untrusted`: the stream
reports every σ as :data:`UNTRUSTED_SD_RAD`). :class:`Monitors` holds a stream's monitors, counts each one's trips
(a change to a level above OK) and hands out the trips not yet reported, so the node logs each one once.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass
from enum import IntEnum
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

#: rad; the σ of every axis while a monitor says the estimate is not to be trusted: half a turn, the σ of an
#: unobservable angle (the yaw of a 6D estimate has it too), so a consumer that weighs by the covariance ignores it
UNTRUSTED_SD_RAD = math.pi


class Level(IntEnum):
    """A monitor's level, as ``diagnostic_msgs/DiagnosticStatus`` has them."""

    OK = 0
    WARN = 1
    ERROR = 2


@dataclass(frozen=True)
class Verdict:
    """A monitor's verdict: its name, level, message (cause and fix; empty while OK) and whether the estimate is
    then not to be trusted (every σ :data:`UNTRUSTED_SD_RAD`)."""

    name: str
    level: Level = Level.OK
    message: str = ""
    untrusted: bool = False


class Monitor(Protocol):
    """A monitor: its name and its current verdict."""

    NAME: str

    def verdict(self) -> Verdict:
        """The verdict now."""
        ...


#: samples between two looks at the verdicts (:meth:`Monitors.tick`): a verdict is a judgement over seconds of input,
#: and a look at every sample would cost as much as a classical filter's step
CHECK_EVERY = 8


class Monitors:
    """A stream's monitors: their verdicts, the trips each made, the σ they widen."""

    def __init__(self, monitors: list[Monitor]) -> None:
        self.monitors = monitors
        self._ticks = 0
        self.trips: Counter[str] = Counter()  # per monitor, how often it went from OK to WARN or ERROR
        self._levels = {m.NAME: Level.OK for m in monitors}
        self._new: list[Verdict] = []  # trips (and recoveries) not yet taken by pop_changes()
        self.untrusted = False  # a verdict says the estimate is not to be trusted

    def tick(self) -> None:
        """After each sample: :meth:`check` every :data:`CHECK_EVERY` samples (the same samples in the node's path and
        the evaluator's: both tick per sample)."""
        self._ticks += 1
        if self._ticks >= CHECK_EVERY:
            self._ticks = 0
            self.check()

    def check(self) -> None:
        """Take every monitor's verdict now."""
        untrusted = False
        for m in self.monitors:
            v = m.verdict()
            untrusted = untrusted or v.untrusted
            old = self._levels[m.NAME]
            if v.level != old:
                self._levels[m.NAME] = v.level
                if old == Level.OK:
                    self.trips[m.NAME] += 1
                self._new.append(v)
        self.untrusted = untrusted

    def verdicts(self) -> list[Verdict]:
        """Every monitor's verdict now."""
        return [m.verdict() for m in self.monitors]

    def level(self) -> Level:
        """The highest level of the verdicts."""
        return max((v.level for v in self.verdicts()), default=Level.OK)

    def pop_changes(self) -> list[Verdict]:
        """The verdicts that changed level since the last call (a trip, a recovery), oldest first."""
        out, self._new = self._new, []
        return out

    def widened(self, sigma: NDArray[np.float64]) -> NDArray[np.float64]:
        """``sigma`` (…, 2: inclination and heading) as the verdicts leave it: every σ :data:`UNTRUSTED_SD_RAD` while
        one says the estimate is not to be trusted."""
        if not self.untrusted:
            return sigma
        out = np.array(sigma, dtype=float, copy=True)
        out[..., :2] = UNTRUSTED_SD_RAD
        return out
