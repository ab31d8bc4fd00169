"""The magnetometer's front end: one per stream, the one driver of the online calibration, shared by every estimator
(ROS-free).

Between the magnetometer input (:mod:`.input`: pairing, units, plausibility, ``use_mag``) and an estimator that uses
the field, the front end does, per sample, what every estimator's field needs:

* **the calibration** (:class:`~.online.OnlineMagCalibrator`, when ``mag_calibration`` is on): the raw reading goes
  in with the sample's bias-corrected gyro increment and the sensor's tilt; the calibrated field comes out, with the
  heading σ the calibration adds (:meth:`MagFrontEnd.heading_sd`) and the calibrated field's own σ
  (:meth:`MagFrontEnd.field_sd_t`);
* **the latency** of the magnetometer behind the gyro (:class:`~.latency.LatencyEstimator`): the calibration's
  windows end at it, and where the estimator asks for it (:class:`LatencySettings`) the field is rotated back over it
  by the gyro (:class:`~.latency.DelayHistory`);
* **the tilt** the calibration needs: the estimator's own attitude where it gives one (RIANN: its network's
  inclination, a typed input of :meth:`MagFrontEnd.step`), else the front end's own (:class:`~.tilt.TiltFilter`);
* **typed change events**: :class:`FieldOut.switched` where the configured calibration was rejected or restored,
  :class:`~.changes.Realign` where the calibration a filter's heading was built on changed (:mod:`.changes`).

Two ways in, one kernel (:meth:`MagFrontEnd._sample`): :meth:`MagFrontEnd.step`, one sample at a time inside an
estimator's loop (RIANN's heading stage, which gives its attitude and whether its disturbance test passed the last
field: the latency fit needs an undisturbed one), and :meth:`MagFrontEnd.rows`, a batch of rows before a classical
filter runs (Madgwick, Mahony, VQF: the tilt is the front end's own, every field goes to the latency fit, the field
is not rotated back). The estimators know the front end's records, never the calibrator.

The calibration belongs to the robot, not to a run of the filter: the estimator's reset keeps its estimate.
:meth:`MagFrontEnd.restart` drops the open window (a hole, a gap), :meth:`MagFrontEnd.reset` also the latency fit
and the gyro history (RIANN's reset). :meth:`MagFrontEnd.snapshot` and :meth:`MagFrontEnd.restore` hold the whole
state as one record. docs/magnetometer.md has the physics.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from collections.abc import Mapping
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from riann_ros.magcal.changes import ChangeFollower, Realign
from riann_ros.magcal.input import calibrated
from riann_ros.magcal.lag import RESOLUTION_S, LagScan
from riann_ros.magcal.latency import DelayHistory, LatencyEstimator
from riann_ros.magcal.online import OnlineMagCalibrator
from riann_ros.magcal.records import (
    DELAY_SD_S,
    HARD_IRON_PRIOR_SD_T,
    UT,
    MagCalibration,
    MagCalPrior,
    MagCalStatus,
    SoftIronModel,
)
from riann_ros.magcal.tilt import TiltFilter
from riann_ros.rotations import Quat, Vec, from_rotvec, rotate


@dataclasses.dataclass(frozen=True)
class FrontEndConfig:
    """The online calibration's settings (the estimators' ``mag_calibration``, ``mag_soft_iron_model`` and
    ``mag_hard_iron_sd`` parameters, :data:`~.input.MAG_CAL_PARAMS`); ``test``: with the calibration off, run its
    gyro-aided test of the configured calibration as a monitor (the field keeps the configured calibration; the
    heading's σ and the stream's monitor say when the test rejects it)."""

    calibrate: bool = True
    soft_iron_model: SoftIronModel = "full"
    hard_iron_sd_t: float = HARD_IRON_PRIOR_SD_T
    test: bool = True
    max_lag_s: float = 0.5  # s; the lag scan's range: the pairing's mag_timeout (a later reading is never paired)

    @classmethod
    def of(cls, params: Mapping[str, Any], max_lag_s: float = 0.5) -> FrontEndConfig:
        """From an estimator's parameters (their defaults where it has none of them) and the pairing's timeout."""
        return cls(bool(params.get("mag_calibration", True)), params.get("mag_soft_iron_model", "full"),
                   float(params.get("mag_hard_iron_sd", HARD_IRON_PRIOR_SD_T)), max_lag_s=max_lag_s)


@dataclasses.dataclass(frozen=True)
class LatencySettings:
    """What the estimator does with the magnetometer's latency: ``start_s`` the fixed latency or the estimate's
    starting value, ``estimate`` estimate it online, ``compensate`` rotate the field back over it (while it is
    estimated or ``start_s`` > 0). The calibration's windows end at the estimate either way."""

    start_s: float = 0.0
    estimate: bool = True
    compensate: bool = False


class FieldOut(NamedTuple):
    """:meth:`MagFrontEnd.step`'s output: the field (calibrated, rotated back over the latency where compensated;
    None: no field), and whether the configured calibration was rejected or restored at this sample."""

    field_t: Vec | None
    switched: bool


class FieldRows(NamedTuple):
    """:meth:`MagFrontEnd.rows`' output: per row the calibrated field (None: no field, and none while the
    calibration says the field's heading is unknown: the filter's gyro holds it) and the heading σ the calibration
    adds (rad; 0 while the configured calibration holds), the rows where the filter checks its heading, and per row the
    doubt of the field's timing the reported σ carries."""

    field: list[Vec | None]
    sd_rad: NDArray[np.float64]
    realign: tuple[Realign, ...]
    timing_sd_rad: NDArray[np.float64]  # the doubt of the field's timing (MagFrontEnd.timing_sd): for the σ only


@dataclasses.dataclass(frozen=True)
class FrontEndState:
    """The front end's whole state (:meth:`MagFrontEnd.snapshot`)."""

    cal: OnlineMagCalibrator | None
    latency: LatencyEstimator
    delays: DelayHistory
    lag: LagScan
    tilt: Quat | None
    seen: bool
    follower: ChangeFollower
    trusted: bool
    scanned: float | None  # the lag the calibration's windows are taken at (None: the latency fit's)


class MagFrontEnd:
    """The magnetometer's front end (module docstring): ``config`` the calibration's settings, ``prior`` where it
    starts (the configured or a saved calibration), ``latency`` what the estimator does with the latency."""

    def __init__(self, config: FrontEndConfig | None = None, prior: MagCalPrior | None = None,
                 latency: LatencySettings | None = None) -> None:
        self.config = config or FrontEndConfig()
        self.latency_settings = latency or LatencySettings()
        self.latency = LatencyEstimator()
        self.delays = DelayHistory()
        self.lag = LagScan(self.config.max_lag_s)
        self.tilt = TiltFilter()
        self.seen = False  # a field has come (rows(): from then on every row goes to the calibration)
        self.cal: OnlineMagCalibrator | None = None
        self.follower = ChangeFollower()
        self.trusted = True  # the configured calibration was in use at the last step()
        self.set_prior(prior or MagCalPrior())

    # -- settings and outputs ----------------------------------------------------------------------------------
    @property
    def calibrating(self) -> bool:
        """The calibrator runs: the field is calibrated online, or it gets the configured calibration here while the
        test runs as a monitor (:attr:`monitoring`); the stream then passes the raw field."""
        return self.cal is not None

    @property
    def monitoring(self) -> bool:
        """The calibrator runs as a monitor only (``mag_calibration`` off): the field always gets the configured
        calibration, and :attr:`trusted` stays true."""
        return self.cal is not None and self.cal.fixed

    def estimate_hard_iron_t(self) -> tuple[float, float, float]:
        """T; the hard iron the windows point to (the estimate's, whether or not the readings get it)."""
        cal = self.cal
        assert cal is not None
        h = cal.model.split(cal.theta)[1]
        return (float(h[0]) * UT, float(h[1]) * UT, float(h[2]) * UT)

    def set_prior(self, prior: MagCalPrior) -> None:
        """Start the calibration anew from ``prior`` (a saved calibration's covariance widens the test's tolerance);
        its hard iron's σ should it be wrong is the config's. Nothing else of the state changes."""
        prior = dataclasses.replace(prior, hard_iron_sd_t=self.config.hard_iron_sd_t)
        self.prior = prior
        self.relag = False  # the lag the field is compensated by moved: the next field checks the heading
        self.scanned = self.lag.late(RESOLUTION_S)  # the lag the calibration's windows are taken at (None: fit's)
        cfg = self.config
        on = cfg.calibrate or cfg.test
        self.cal = OnlineMagCalibrator(prior, cfg.soft_iron_model, fixed=not cfg.calibrate) if on else None
        self.follower = ChangeFollower()
        self.trusted = True

    def calibration(self) -> MagCalibration | None:
        """The calibration in use as a record (what ``~/save_mag_calibration`` writes); None when off."""
        return self.cal.calibration() if self.cal is not None else None

    def status(self) -> MagCalStatus | None:
        """The calibration's state for ``/diagnostics``; None when off."""
        return self.cal.status() if self.cal is not None else None

    @property
    def delay_s(self) -> float:
        """s; the latency the latency fit compensates now: the estimate, or the fixed value when it is not estimated
        (a field the lag scan finds late is compensated by the scanned lag instead, :attr:`late_s`)."""
        ls = self.latency_settings
        return self.latency.delay(ls.start_s) if ls.estimate else ls.start_s

    @property
    def late_s(self) -> float | None:
        """s; the lag of a field the lag scan finds late (beyond its resolution: the scan compensates it, exactly,
        for every estimator), else None."""
        return self.lag.late(RESOLUTION_S)

    # -- restarts and state ------------------------------------------------------------------------------------
    def restart(self) -> None:
        """A hole or a gap: the calibration's open window is dropped, its estimate kept."""
        if self.cal is not None:
            self.cal.restart()

    def reset(self) -> None:
        """The estimator's reset: :meth:`restart`, and the latency fit, the lag scan and the gyro history anew."""
        self.latency.reset()
        self.delays.reset()
        self.lag.reset()
        self.restart()

    def snapshot(self) -> FrontEndState:
        """The whole state, as a record independent of this front end (:meth:`restore` takes it back)."""
        return copy.deepcopy(FrontEndState(self.cal, self.latency, self.delays, self.lag, self.tilt.q, self.seen,
                                           self.follower, self.trusted, self.scanned))

    def restore(self, state: FrontEndState) -> None:
        s = copy.deepcopy(state)
        self.cal, self.latency, self.delays, self.lag, self.tilt.q = s.cal, s.latency, s.delays, s.lag, s.tilt
        self.seen, self.follower, self.trusted, self.scanned = s.seen, s.follower, s.trusted, s.scanned

    # -- per sample --------------------------------------------------------------------------------------------
    def _sample(self, delta: Quat, rv: Vec, dt: float, raw: Vec | None, q: Quat | None,
                undisturbed: bool) -> Vec | None:
        """The kernel of both ways in: the raw reading through the calibration (the windows end at the latency
        estimate), then this sample into the latency fit (with the field where ``undisturbed``)."""
        lat = self.latency
        late = self.late_s
        if moved(self.scanned, late) and self.cal is not None:  # windows taken at another lag: the calibration
            self.set_prior(self.prior)  # anew, and the heading is checked against the field now compensated
            self.relag = True
        u = raw
        if self.cal is not None:
            delay = lat.delay(self.latency_settings.start_s) if late is None else late
            u = self.cal.update(delta, dt, raw, delay, q, lat.sd(DELAY_SD_S))
        if self.latency_settings.estimate or self.cal is not None:
            lat.add(delta, rv, dt, u if undisturbed else None)
        self.lag.add(delta, dt, raw if self.cal is None else configured(self.prior, raw))
        self.lag.track_doubt(q, rv, dt)
        return u

    def step(self, delta: Quat, rv: Vec, dt: float, raw: Vec | None, q: Quat, undisturbed: bool) -> FieldOut:
        """One sample inside an estimator's loop: ``delta`` its bias-corrected gyro increment and ``rv`` that
        increment's rotation vector, ``dt`` its step (s), ``raw`` its field (T; None: none), ``q`` the estimator's
        attitude (sensor → world; only its tilt is read), ``undisturbed`` whether the estimator's disturbance test
        passed the last field."""
        u = self._sample(delta, rv, dt, raw, q, undisturbed)
        switched = self.cal is not None and (self.trusted != self.cal.trusted or (self.relag and u is not None))
        self.relag = self.relag and u is None
        if switched:
            assert self.cal is not None
            self.trusted = self.cal.trusted
        ls = self.latency_settings
        if ls.compensate and (ls.estimate or ls.start_s > 0.0):
            r = self.delays.rotation(delta, dt, self.delay_s)
            if u is not None and self.late_s is None:
                u = rotate((r[0], -r[1], -r[2], -r[3]), u)
        return FieldOut(self._late(u), switched)

    def _late(self, u: Vec | None) -> Vec | None:
        """A field the lag scan finds late (beyond its resolution), rotated back over the scanned lag (:mod:`.lag`,
        exact; the latency fit is first order and sees a few tens of ms); else ``u``."""
        late = self.late_s
        return u if late is None or u is None else self.lag.compensated(u, late)

    def heading_sd(self, q: Quat, field_world_t: Vec) -> float:
        """rad; the σ the calibration adds to the heading of this sample's field (``q`` its attitude,
        ``field_world_t`` the calibrated field in the world frame, T); 0 without the online calibration."""
        return self.cal.heading_sd_rad(q, field_world_t) if self.cal is not None else 0.0

    @property
    def timing_sd(self) -> float:
        """rad; the heading's doubt from the field's timing while the lag scan had not resolved it
        (:attr:`.lag.LagScan.doubt_sd`): the reported σ carries it; the estimators weigh the field without it."""
        return self.lag.doubt_sd

    def field_sd_t(self) -> float:
        """T; the calibrated field's σ in its worst direction (0 while the configured calibration is used, and
        without the online calibration)."""
        return self.cal.field_sd_t() if self.cal is not None else 0.0

    # -- a batch of rows ---------------------------------------------------------------------------------------
    def takes(self, mag: object) -> bool:
        """Whether a batch goes through :meth:`rows`: the calibration is on, and the batch has a field or one came
        before (until the first field it would pass every row by)."""
        return self.cal is not None and (mag is not None or self.seen)

    def rows(self, acc: list, gyr: list, dt: list, mag: list) -> FieldRows:
        """The classical filters' way in: ``acc``, ``gyr`` (bias-corrected where the filter corrects it), ``dt`` and
        the raw ``mag`` rows (a zero row or None: no field), as lists of plain floats → :class:`FieldRows`."""
        assert self.cal is not None
        out: list[Vec | None] = []
        sd: list[float] = []
        timing: list[float] = []
        realign: list[Realign] = []
        for i, ((ax, ay, az), (gx, gy, gz), h, m) in enumerate(zip(acc, gyr, dt, mag, strict=True)):
            field = None if m is None or not (m[0] or m[1] or m[2]) else (m[0], m[1], m[2])
            self.seen = self.seen or field is not None
            if not self.seen:  # nothing before the first field (a filter fed one sample at a time does not call it)
                out.append(None)
                sd.append(0.0)
                timing.append(self.lag.doubt_sd)
                continue
            rv = (gx * h, gy * h, gz * h)
            if not math.isfinite(rv[0] * rv[0] + rv[1] * rv[1] + rv[2] * rv[2]):
                self.cal.restart()  # a turn no window can hold (a degenerate gyro sample): the open window goes
                out.append(None)
                sd.append(0.0)
                timing.append(self.lag.doubt_sd)
                continue
            delta = from_rotvec(*rv)
            q = self.tilt.step(delta, h, ax, ay, az)
            u = self._late(self._sample(delta, rv, h, field, q, True))
            cal = self.cal  # (the sample may have started the calibration anew: a lag the scan found moved)
            s = 0.0 if u is None or q is None else cal.heading_sd_rad(q, rotate(q, u))
            if s >= math.pi and not cal.fixed:  # the field's heading is unknown (the last window contradicted it)
                u, s = None, 0.0
            event = self.follower.event(i, cal.changes, u is not None, s)
            if self.relag and u is not None:  # the field's instant changed: checked against its own σ only
                event, self.relag = Realign(i, 0.0), False
            if event is not None:
                realign.append(event)
            out.append(u)
            sd.append(s)
            timing.append(self.lag.doubt_sd)
        return FieldRows(out, np.asarray(sd, dtype=float), tuple(realign), np.asarray(timing, dtype=float))


def configured(prior: MagCalPrior, raw: Vec | None) -> Vec | None:
    """The raw field (T) through the configured (or saved) calibration, ``S (m − h)``: what the lag scan reads, so
    that an online estimate taken at a wrong lag never blurs the scan that finds the lag."""
    return None if raw is None else calibrated(prior.hard_iron_t, prior.soft_iron, raw[0], raw[1], raw[2])


def moved(before: float | None, now: float | None) -> bool:
    """Whether the lag the calibration's windows are taken at moved by more than the scan's resolution (or between
    the latency fit's and the scan's): its windows then hold fields of another instant."""
    if before is None or now is None:
        return before is not now
    return abs(now - before) > RESOLUTION_S
