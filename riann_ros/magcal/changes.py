"""When the calibration a field gets changes under a heading built on the one before, and the typed event that tells
a filter to check its heading (ROS-free).

A filter's heading follows the field it was given with the filter's own gain (Madgwick's β, Mahony's k_P, VQF's
``tau_mag``), from where the calibration before took it. When the calibration the readings get changes — a decision
(the configured calibration found the less probable hypothesis, or restored; a candidate replacing the estimate) or
the one in use turning the heading of the last reading by more than the field heading's σ (:class:`Changes`, kept
by the calibrator per window) — the front end marks the next row with a field with a :class:`Realign` event
(:class:`ChangeFollower`), carrying the heading σ the calibration adds there, and the filter checks its heading
against that row's field: if the two differ by more than :data:`REALIGN_SIGMAS` times the calibration's and the
field's own σ combined (:func:`field_disagrees`), the heading is set from the field as at the filter's start. While
the calibration's σ is above the field heading's σ the check is repeated at each window, so a heading built on a
wrong calibration is set anew once the new one is known well enough to tell; a change the filter's heading already
agrees with moves nothing.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from riann_ros.magcal.heading import field_heading, heading_of
from riann_ros.magcal.records import FIELD_HEADING_SD_RAD
from riann_ros.rotations import Quat, Vec

#: a filter's heading is set anew from the field where the calibration changed only if the two differ by more than
#: this many σ (:func:`field_disagrees`): a change the filter's heading already agrees with does not move it
REALIGN_SIGMAS = 3.0

Applied = tuple[tuple[float, ...], tuple[float, ...]]  # a calibration as applied: row-major soft iron, hard iron µT


class Realign(NamedTuple):
    """The calibration the field gets changed: before row ``row`` of a batch the filter checks its heading against
    that row's field; ``sd_rad`` is the heading σ the calibration adds there."""

    row: int
    sd_rad: float


class Changes:
    """The calibrator's record of changes (module docstring): :attr:`count` the changes, by a decision or because
    the calibration in use turned the heading of the last reading, at the current tilt, by more than the field
    heading's own σ since the last change; :attr:`closed` the windows closed."""

    def __init__(self, in_use: Applied) -> None:
        self.count = 0
        self.closed = 0
        self.aligned = in_use  # the calibration at the last change

    def window(self, decided: bool, in_use: Applied, m: Vec | None, q: Quat | None) -> None:
        """After a window: ``decided`` whether the readings got another calibration, ``in_use`` the calibration they
        get, ``m`` the last raw reading (µT) and ``q`` the attitude (sensor → world)."""
        self.closed += 1
        if not decided and m is not None and q is not None:
            turn = heading_of(*in_use, m, q) - heading_of(*self.aligned, m, q)
            decided = abs(math.remainder(turn, math.tau)) > FIELD_HEADING_SD_RAD
        if decided:
            self.count += 1
            self.aligned = in_use


class ChangeFollower:
    """Which rows carry a :class:`Realign` event (module docstring): the first row with a field after a change, and
    while the calibration's σ there was above the field heading's, the first after each window since."""

    def __init__(self) -> None:
        self.changes = 0  # the change count the filter's heading follows
        self.pending = False  # a change not yet followed (no field since)
        self.unsettled = False  # the last check was made with a σ above the field heading's
        self.closed = 0  # the window count at the last check

    def event(self, row: int, changes: Changes, has_field: bool, sd_rad: float) -> Realign | None:
        """The event of row ``row`` (``has_field``: the row has a calibrated field, ``sd_rad`` the heading σ the
        calibration adds to it), given the calibrator's :class:`Changes` after the row."""
        if changes.count != self.changes or (self.unsettled and changes.closed != self.closed):
            self.changes, self.closed, self.pending = changes.count, changes.closed, True
        if not (self.pending and has_field):
            return None
        self.pending = False
        self.unsettled = sd_rad > FIELD_HEADING_SD_RAD  # checked again at each window until the σ allows
        return Realign(row, sd_rad)


def field_disagrees(q: Quat, m: Vec, sd_rad: float) -> bool:
    """Whether the heading of the attitude ``q`` (sensor → ENU) and that of the field ``m`` (sensor frame) differ by
    more than :data:`REALIGN_SIGMAS` times their σ: the calibration's ``sd_rad`` and the field heading's own."""
    psi = field_heading(q, m)
    return psi is not None and abs(psi) > REALIGN_SIGMAS * math.hypot(sd_rad, FIELD_HEADING_SD_RAD)
