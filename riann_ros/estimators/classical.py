"""What Madgwick, Mahony and VQF share: one ``update_batch`` skeleton, the field from the magnetometer's front end, and
a σ with the calibration's share (ROS-free).

Every classical filter runs a batch the same way (:meth:`ClassicalFilter.update_batch`):

1. the inputs sanitised (:func:`~.common.sanitize_arrays`: the documented degenerate-input rules);
2. the gyro as the filter integrates it (:meth:`ClassicalFilter._debiased`: Madgwick's and Mahony's optional
   bias front end, :mod:`.bias`; VQF estimates its bias itself);
3. the field: with the stream's front end calibrating online (:class:`~riann_ros.magcal.frontend.MagFrontEnd`), its
   calibrated rows, the heading σ the calibration adds per row, and the :class:`~riann_ros.magcal.changes.Realign`
   events where the filter checks its heading against the field; else the field as the stream gave it;
4. the filter over the batch, cut before each realign row (:func:`~.common.cut_at`): each filter applies the event
   to its own state (Madgwick and Mahony: :func:`~.common.realigned`, their tilt kept; VQF: its magnetic part
   restarted).

The heading's σ (:meth:`ClassicalFilter.sigma`) is the documented constant with a field, with the calibration's
share and the error the filter's disagreement with its own field shows (:mod:`.heading_consistency`) added in
quadrature (capped at the σ of a free heading).
"""

from __future__ import annotations

from abc import abstractmethod
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from riann_ros.defaults import INCLINATION_SD_DEG, MAG_HEADING_SD_DEG, YAW_FREE_SD_DEG
from riann_ros.estimators.base import Array, AttitudeEstimator
from riann_ros.estimators.common import sanitize_arrays, sanitize_mag
from riann_ros.estimators.heading_consistency import HeadingConsistency
from riann_ros.magcal.changes import Realign

_MAG_SD = float(np.radians(MAG_HEADING_SD_DEG))  # rad; a calibrated field heading's σ


class Batch(NamedTuple):
    """One batch as the skeleton hands it to a filter: the sanitised inputs (arrays), the same as lists of plain
    floats where the front end needed them (else None), the field per row (a row None or zeros: no field; None: no
    field at all, a 6D call) and the realign events."""

    acc: Array
    gyr: Array
    dt: Array
    lists: tuple[list, list, list] | None
    mag: list | None
    realign: tuple[Realign, ...]

    def as_lists(self) -> tuple[list, list, list]:
        """acc, gyr and dt as lists of plain floats."""
        return self.lists if self.lists is not None else (self.acc.tolist(), self.gyr.tolist(), self.dt.tolist())


class ClassicalFilter(AttitudeEstimator):
    """The skeleton of Madgwick, Mahony and VQF (module docstring): a subclass gives :meth:`_run`, and
    :meth:`_debiased` where it has a bias front end."""

    USES_MAG = True

    def __init__(self, **params: Any) -> None:
        # per row of the last batch: the field heading's σ with the calibration's share, and the heading σ the
        # field's disagreement shows
        self._field_sd: NDArray[np.float64] = np.zeros(0)
        self._seen_sd: NDArray[np.float64] = np.zeros(0)
        super().__init__(**params)

    def reset(self) -> None:
        self._consistency = HeadingConsistency()
        self._reset_filter()

    @abstractmethod
    def _reset_filter(self) -> None:
        """Forget the filter's own state (:meth:`reset` also starts the heading's consistency anew)."""

    def _debiased(self, acc: Array, gyr: Array, dt: Array) -> Array:
        """The gyro as the filter integrates it (default: as it is)."""
        return gyr

    @abstractmethod
    def _run(self, batch: Batch) -> Array:
        """The filter over a batch: (n, 4) attitudes."""

    def update_batch(self, acc: ArrayLike, gyr: ArrayLike, dt: ArrayLike, mag: ArrayLike | None = None) -> Array:
        batch = self._batch(acc, gyr, dt, mag)
        q = self._run(batch)
        if batch.mag is not None:
            self._seen_sd = self._consistency.run(q, batch.mag, batch.dt, self._field_sd)
        return q

    def _batch(self, acc: ArrayLike, gyr: ArrayLike, dt: ArrayLike, mag: ArrayLike | None) -> Batch:
        """Steps 1–3 of the skeleton (module docstring)."""
        a, g, h = sanitize_arrays(acc, gyr, dt)
        g = self._debiased(a, g, h)
        m = None if mag is None else sanitize_mag(mag, len(a))
        self._field_sd, self._seen_sd = np.full(len(a), _MAG_SD), np.zeros(0)
        front = self.front
        if front is None or not front.takes(mag):
            return Batch(a, g, h, None, m, ())
        lists = (a.tolist(), g.tolist(), h.tolist())
        rows = front.rows(*lists, [None] * len(a) if m is None else m)
        # the calibration's share (the filter weighs the field without it)
        self._field_sd = np.hypot(_MAG_SD, np.hypot(rows.sd_rad, rows.timing_sd_rad))
        return Batch(a, g, h, lists, rows.field, rows.realign)

    def sigma(self, fields: NDArray[np.bool_]) -> Array:
        """The documented constants, the heading's with a field widened by the calibration's share and by the error
        the filter's disagreement with its own field shows (the module docstring)."""
        f = np.asarray(fields, dtype=bool)
        mag_sd = self._field_sd if len(self._field_sd) == len(f) else np.full(len(f), _MAG_SD)
        if len(self._seen_sd) == len(f):  # the error the disagreement with the field shows
            mag_sd = np.hypot(mag_sd, self._seen_sd)
        yaw = np.where(f, np.minimum(mag_sd, np.radians(YAW_FREE_SD_DEG)), np.radians(YAW_FREE_SD_DEG))
        return np.column_stack([np.full(len(f), np.radians(INCLINATION_SD_DEG)), yaw])

