"""The online magnetometer calibration in an estimator (ROS-free): one :class:`MagCalSlot` per 9D estimator.

The slot owns the estimator's :class:`~riann_ros.magcal.online.OnlineMagCalibrator` (built from the estimator's
:data:`~riann_ros.mag.MAG_CAL_PARAMS` and the prior the stream gives it, :meth:`MagCalSlot.set_prior`). It belongs
to the robot, not to a run of the filter: a reset keeps the estimate (its open window is dropped), and so does a
hole or a gap.

RIANN's heading stage (:mod:`~riann_ros.estimators.riann.s7a_mag`) calls the calibrator per sample itself (it has
the attitude and the magnetometer's latency). Madgwick, Mahony and VQF get it as a front end
(:meth:`MagCalSlot.calibrate`), like the gyro-bias front end (:mod:`.bias`): per sample the gyro increment goes to
the calibrator (with the field's latency behind the gyro estimated as RIANN's stage 7b does, for the windows'
ends; the filters themselves use the field as it comes), the filter gets the calibrated field, and
:attr:`MagCalSlot.sd_rad` holds the σ the calibration
adds to each sample's heading (0 while the configured calibration holds), which their yaw σ includes.

A filter's heading follows the field it was given with the filter's own gain (Madgwick's β, Mahony's k_P, VQF's
``tau_mag``), from where the calibration before took it. When the calibration the field gets changes — a decision
(the configured calibration found the less probable hypothesis, or restored; a candidate replacing the estimate) or
the one in use turning the heading of the last reading by more than the field heading's σ
(:class:`~riann_ros.magcal.online.Changes`) — the slot marks the next row with a field (:attr:`MagCalSlot.realign`,
with the calibration's heading σ there), and the filter checks its heading against that row's field: if they differ
by more than three times the calibration's and the field's own σ combined, the heading is set from the field as at
the filter's start (Madgwick and Mahony: :func:`~.common.align_heading`, the filter's tilt kept; VQF: its magnetic
part restarted as at its construction, so its heading initialises over ``tau_mag``). While the calibration's σ is
above the field heading's σ the check is repeated at each window, so a heading built on a wrong calibration is set
anew once the new one is known well enough to tell; a change the filter's heading already agrees with moves nothing.
A configured calibration the windows keep never changes: the filter's attitude is the one without the calibration.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from riann_ros.magcal.latency import LatencyEstimator
from riann_ros.magcal.online import OnlineMagCalibrator
from riann_ros.magcal.records import DELAY_SD_S, FIELD_HEADING_SD_RAD, MagCalibration, MagCalPrior, MagCalStatus
from riann_ros.rotations import Quat, from_rotvec, normalized, qmul, rotate

#: s; the time constant with which the calibration's attitude follows the accelerometer (VQF's tauAcc default)
TILT_TAU_S = 3.0


class MagCalSlot:
    """The calibration of one estimator (module docstring); off when its ``mag_calibration`` parameter is."""

    def __init__(self, params: dict[str, Any]) -> None:
        self.on = bool(params["mag_calibration"])
        self.model = params["mag_soft_iron_model"]
        self.hard_iron_sd_t = float(params["mag_hard_iron_sd"])
        self.cal: OnlineMagCalibrator | None = None
        self.latency = LatencyEstimator()  # the windows' ends need the field's latency behind the gyro (stage 7b's fit)
        self.q: Quat | None = None  # the calibration's attitude (:meth:`_tilt`)
        self.seen = False  # a field has come: from then on every sample goes to the calibration
        # per sample of the last calibrate(): the heading σ the calibration adds (rad)
        self.sd_rad: NDArray[np.float64] = np.zeros(0)
        #: the rows of the last calibrate() before which the filter's heading is set anew from the row's field: the
        #: first row with a field after the calibration the field gets changed (module docstring)
        self.realign: tuple[tuple[int, float], ...] = ()
        self._changes = 0  # the calibrator's change count the filter's heading follows
        self._pending = False  # a change not yet followed (no field since)
        self._unsettled = False  # the last check was made with a σ above the field heading's
        self._closed = 0  # the calibrator's window count at the last check
        self.set_prior(MagCalPrior())

    def set_prior(self, prior: MagCalPrior) -> None:
        """Start the calibration anew from ``prior`` (the configured ``mag_hard_iron`` / ``mag_soft_iron``, or a
        saved calibration, whose covariance widens the test's tolerance); the hard iron's σ should the prior be
        wrong is the ``mag_hard_iron_sd`` parameter."""
        prior = dataclasses.replace(prior, hard_iron_sd_t=self.hard_iron_sd_t)
        self.cal = OnlineMagCalibrator(prior, self.model) if self.on else None
        self._changes, self._pending, self._unsettled, self._closed = 0, False, False, 0

    def restart(self) -> None:
        """A reset, a gap or a hole: the open window is dropped, the estimate kept; the attitude starts anew."""
        self.q = None
        if self.cal is not None:
            self.cal.restart()

    def calibration(self) -> MagCalibration | None:
        return self.cal.calibration() if self.cal is not None else None

    def status(self) -> MagCalStatus | None:
        return self.cal.status() if self.cal is not None else None

    def takes(self, mag: object) -> bool:
        """Whether a batch goes to the calibration: it is on, and the batch has a field or one came before (until the
        first field it would pass every sample by)."""
        return self.on and (mag is not None or self.seen)

    def calibrate(self, acc: list, gyr: list, dt: list, mag: list) -> list:
        """The classical filters' front end: ``acc``, ``gyr`` (bias-corrected where the filter corrects it), ``dt``
        and the raw ``mag`` rows (a zero row or None: no field) → the calibrated rows (None: no field, and none
        while the calibration says the field's heading is unknown: the filter's gyro holds it); the heading σ the
        calibration adds per sample (the doubt about the configured calibration while it is used) into
        :attr:`sd_rad`; the rows where the filter's heading is set anew into :attr:`realign`."""
        cal = self.cal
        assert cal is not None
        out: list = []
        sd = []
        realign = []
        lat = self.latency
        for i, ((ax, ay, az), (gx, gy, gz), h, m) in enumerate(zip(acc, gyr, dt, mag, strict=True)):
            field = None if m is None or not (m[0] or m[1] or m[2]) else (m[0], m[1], m[2])
            self.seen = self.seen or field is not None
            if not self.seen:  # nothing before the first field (a filter fed one sample at a time does not call it)
                out.append(None)
                sd.append(0.0)
                continue
            rv = (gx * h, gy * h, gz * h)
            if not math.isfinite(rv[0] * rv[0] + rv[1] * rv[1] + rv[2] * rv[2]):
                cal.restart()  # a turn no window can hold (a degenerate gyro sample): the open window goes
                out.append(None)
                sd.append(0.0)
                continue
            delta = from_rotvec(*rv)
            q = self._tilt(delta, h, ax, ay, az)
            u = cal.update(delta, h, field, lat.delay(0.0), q, lat.sd(DELAY_SD_S))
            lat.add(delta, rv, h, u)
            s = 0.0 if u is None or q is None else cal.heading_sd_rad(q, rotate(q, u))
            if s >= math.pi:  # the field's heading is unknown (the last window contradicted the estimate)
                u, s = None, 0.0
            ch = cal.changes
            if ch.count != self._changes or (self._unsettled and ch.closed != self._closed):
                self._changes, self._closed, self._pending = ch.count, ch.closed, True
            if self._pending and u is not None:
                realign.append((i, s))
                self._pending = False
                self._unsettled = s > FIELD_HEADING_SD_RAD  # checked again at each window until the σ allows
            out.append(u)
            sd.append(s)
        self.sd_rad = np.asarray(sd, dtype=float)
        self.realign = tuple(realign)
        return out

    def _tilt(self, delta: Quat, dt: float, ax: float, ay: float, az: float) -> Quat | None:
        """The calibration's attitude (only its tilt matters): the gyro carries it and the accelerometer pulls it
        toward gravity with the time constant :data:`TILT_TAU_S` (a linear acceleration, a tap, does not tilt it;
        the accelerometer alone does not know gravity while the sensor accelerates); the first accelerometer sample
        sets it."""
        n = math.sqrt(ax * ax + ay * ay + az * az)
        if self.q is None:
            self.q = _tilt(ax, ay, az)
            return self.q
        q = normalized(qmul(self.q, delta))
        if 0.0 < n < math.inf:
            ux, uy, uz = rotate(q, (ax / n, ay / n, az / n))  # the measured "up" in the world frame
            k = min(dt / TILT_TAU_S, 1.0)  # rotate it toward +z by this share of the angle between them
            c = max(-1.0, min(1.0, uz))
            s = math.sqrt(ux * ux + uy * uy)
            if s > 0.0:
                angle = k * math.atan2(s, c)
                q = normalized(qmul(from_rotvec(uy / s * angle, -ux / s * angle, 0.0), q))
        self.q = q
        return q


def _tilt(ax: float, ay: float, az: float) -> Quat | None:
    """The zero-heading attitude of an accelerometer sample (the shortest rotation of its direction onto +z), or
    None without one: the calibration needs only the tilt."""
    n = math.sqrt(ax * ax + ay * ay + az * az)
    if not 0.0 < n < math.inf:
        return None
    w = 1.0 + az / n
    if w < 1e-9:  # upside down: half a turn about x
        return (0.0, 1.0, 0.0, 0.0)
    k = 1.0 / math.sqrt(w * w + (ay / n) ** 2 + (ax / n) ** 2)
    return (w * k, ay / n * k, -ax / n * k, 0.0)
