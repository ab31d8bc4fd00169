"""The online calibration: causal, per sample, gyro-aided (ROS-free).

Per sample (:meth:`OnlineMagCalibrator.update`, plain floats): the gyro increment goes into the open window (one
quaternion product), the reading is calibrated with the current estimate (a 3×3 product). Once per window (numpy,
:meth:`OnlineMagCalibrator._add_window`): the window's innovation is tested against its covariance (the window's
noise plus the estimate's own uncertainty, scaled by the variance of unit weight) and, if it passes, added to the
information-form least squares ``(Λ, η)`` that started from the prior; ``θ = Λ⁻¹ η``, with the windows' information
kept only in the directions they know at least as well as the prior (:func:`~.model.posterior`). Without rotation
no window closes, so the estimate holds at rest and in straight motion; a rotation about one axis only informs what
that rotation observes (the prior keeps the rest). Nothing is forgotten: no drift.

What it knows: ``Λ⁻¹`` (times the variance of unit weight when the windows scatter more than the noise model says)
is the estimate's covariance. :meth:`heading_sd_rad` turns it into the σ it adds to a tilt-compensated heading for
the current attitude and field, per sample (a cached 3×3 field covariance, refreshed every
:data:`REFRESH_ANGLE_RAD` of rotation); the state is *calibrated* once the largest such σ over all headings at the
current tilt is at most :data:`CALIBRATED_SD_RAD`, *uncalibrated* while no window has been added, *converging*
in between.

The prior as a hypothesis (:mod:`.hypothesis`): while the windows are consistent with the configured (or saved)
calibration and make it the more probable hypothesis, the readings are calibrated with it as it is and
:meth:`heading_sd_rad` adds only the doubt they leave (:attr:`trusted`); otherwise with the estimate and its σ, for
good once the test rejects the prior.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from riann_ros.magcal.changes import Changes
from riann_ros.magcal.heading import heading_gap
from riann_ros.magcal.hypothesis import PriorTest
from riann_ros.magcal.model import Array, CalModel, heading_sd_bound
from riann_ros.magcal.records import (
    CALIBRATED,
    CALIBRATED_SD_RAD,
    CONVERGING,
    DELAY_SD_S,
    REFRESH_ANGLE_RAD,
    STATE_HEADINGS,
    SWITCH_WINDOWS,
    UNCALIBRATED,
    USABLE_MAX_T,
    USABLE_MIN_T,
    UT,
    CalState,
    MagCalibration,
    MagCalPrior,
    MagCalStatus,
    SoftIronModel,
)
from riann_ros.magcal.solver import InfoEstimate
from riann_ros.magcal.windows import Window, Windower, WindowSet
from riann_ros.rotations import Quat, Vec, rotate

_COS_REFRESH = math.cos(0.5 * REFRESH_ANGLE_RAD)
#: below this posterior probability that the configured calibration is wrong, its share of the heading σ is none (a
#: millionth of even a 180° doubt is 0.2°: below the field heading's own σ, 2.5°, in quadrature: 0.006°)
UNDOUBTED = 1e-6
_MIN2_UT, _MAX2_UT = (USABLE_MIN_T / UT) ** 2, (USABLE_MAX_T / UT) ** 2  # µT²: riann_ros.magcal.input's plausible norms


class OnlineMagCalibrator:
    """The online calibration (module docstring). ``prior``: the configured or saved calibration;
    ``soft_iron_model``: ``full`` (default: all 3×3 including the magnetometer's misalignment to the gyro, which
    the gyro-aided constraint observes), ``symmetric`` or ``none`` (hard iron only)."""

    def __init__(self, prior: MagCalPrior | None = None, soft_iron_model: SoftIronModel = "full") -> None:
        prior = prior or MagCalPrior()
        self.model = CalModel(soft_iron_model, np.asarray(prior.soft_iron).reshape(3, 3))
        self.lam0, self.theta0 = self.model.prior(dataclasses.replace(prior, covariance=None))  # the estimate's: broad
        self.est = InfoEstimate(self.model, self.lam0, self.theta0)
        saved = None if prior.covariance is None else np.linalg.inv(self.model.prior(prior)[0])  # a saved one's σ
        self.test = PriorTest(self.model, self.theta0, saved)  # does the prior still hold?
        self.agree = 0  # consecutive windows that agree with a rejected prior
        self.cand: InfoEstimate | None = None  # learns from consecutive rejected windows
        self.switches = 0  # times a candidate replaced the estimate
        self.windower = Windower()
        self.windows = prior.windows  # windows in the information (a saved calibration's included)
        self.rejected = 0  # windows rejected as disturbed in this run
        self.converged_after_s: float | None = None  # s after this run's first sample
        self.q: Quat | None = None  # the attitude last passed (the state's tilt)
        self.m_last: Vec | None = None  # the last raw reading (µT)
        self.q_refresh: Quat | None = None  # the windower's attitude at the last field-covariance refresh
        self.su: tuple[float, ...] = (0.0,) * 6  # the cached field covariance (µT²): xx, xy, xz, yy, yz, zz
        self.bound = math.pi  # the last state bound (rad)
        self.field_sd_ut = math.inf  # the calibrated field's σ in its worst direction (µT; refreshed with su)
        self._cache()
        self.changes = Changes((self._a, self._c))  # what a filter's heading built on the field must follow
        self.state: CalState = UNCALIBRATED
        self._set_state()

    # -------------------------------------------------------------------------------------------------- per sample
    def update(self, delta: Quat, dt: float, mag_t: Vec | None, delay_s: float = 0.0, q: Quat | None = None,
               delay_sd_s: float = DELAY_SD_S) -> Vec | None:
        """One sample: ``delta`` the bias-corrected gyro increment (sensor frame), ``dt`` its step (s), ``mag_t``
        the raw field (T; a reading that is not finite or outside riann_ros.magcal.input's plausible 1 µT–1 mT counts as
        none) or None, ``delay_s`` the magnetometer's latency (s) and ``delay_sd_s`` its standard deviation,
        ``q`` the attitude (sensor → world; only its tilt matters) when known. Returns the calibrated field (T) or
        None."""
        if q is not None:
            self.q = q
        m = None
        if mag_t is not None:
            m = (mag_t[0] / UT, mag_t[1] / UT, mag_t[2] / UT)
            n2 = m[0] * m[0] + m[1] * m[1] + m[2] * m[2]
            if not _MIN2_UT <= n2 <= _MAX2_UT:  # not finite (NaN fails too), dead or saturated: no reading
                m = None
        w = self.windower.add(delta, dt, m, delay_s, delay_sd_s)
        if w is not None:
            self._add_window(w)
        if m is None:
            return None
        first = self.m_last is None
        self.m_last = m
        if first:
            self._set_state()
        a, c = self._a, self._c
        x, y, z = m
        return ((a[0] * x + a[1] * y + a[2] * z - c[0]) * UT, (a[3] * x + a[4] * y + a[5] * z - c[1]) * UT,
                (a[6] * x + a[7] * y + a[8] * z - c[2]) * UT)

    def restart(self) -> None:
        """A hole in the gyro stream: the open window is dropped; the estimate is kept."""
        self.windower.restart()

    def heading_sd_rad(self, q: Quat, field_world_t: Vec) -> float:
        """rad; the σ the calibration adds to the heading of this sample (``q`` its attitude, sensor → world;
        ``field_world_t`` its calibrated field, world frame, T): π with a vertical field, and while the last window
        contradicted the estimate (disturbed, or a changed magnetic situation); while the prior is used, the share of
        the doubt about it (:mod:`.hypothesis`)."""
        doubt = 1.0 - self.test.p_holds if self.trusted else 1.0
        if doubt < UNDOUBTED:
            return 0.0
        fx, fy = field_world_t[0], field_world_t[1]
        fh = math.sqrt(fx * fx + fy * fy)
        if fh <= 0.0:
            return math.pi
        if self.trusted:  # the field calibrated as configured: the mixture's share (riann_ros.magcal.hypothesis)
            s1 = self._heading_sd(q, fx / fh, fy / fh, fh)
            d = 0.0 if self.m_last is None else heading_gap(self._est_a, self._est_c, self.m_last, q, field_world_t)
            return min(math.sqrt(doubt * (s1 * s1 + d * d)), math.pi)
        if self.cand is not None:  # the last window contradicted the estimate: disturbed, or the situation changed
            return math.pi
        return self._heading_sd(q, fx / fh, fy / fh, fh)

    def _heading_sd(self, q: Quat, ex: float, ey: float, fh: float) -> float:
        """rad; the estimate's heading σ for the horizontal field direction (ex, ey) of strength ``fh`` (T)."""
        self._maybe_refresh()
        wx, wy, wz = rotate((q[0], -q[1], -q[2], -q[3]), (ey, -ex, 0.0))  # across the field, sensor frame
        s = self.su
        var = (s[0] * wx * wx + s[3] * wy * wy + s[5] * wz * wz
               + 2.0 * (s[1] * wx * wy + s[2] * wx * wz + s[4] * wy * wz))
        return math.sqrt(max(var, 0.0)) * UT / fh

    def field_sd_t(self) -> float:
        """T; the calibrated field's σ in its worst direction for the current orientation: how far its norm and
        dip can be off through the calibration alone (a disturbance test against a learned reference should widen
        its band by a few of these while the calibration converges); 0 while the prior holds."""
        if self.trusted:
            return 0.0
        self._maybe_refresh()
        return self.field_sd_ut * UT

    # -------------------------------------------------------------------------------------------------- per window
    def _add_window(self, w: Window) -> None:
        ws = WindowSet.of([w])
        jw, rw = self.model.rows(ws)
        j, r0 = jw[0], rw[0]
        est = self.est
        trusted = self.trusted
        var = float(self.model.window_var(ws, self.model.soft_iron(est.theta), est.theta[self.model.p:])[0])
        d2, k = est.window(j, r0, var)
        if est.passes(d2):
            est.add(j, r0, var, d2, k)
            self.windows += 1
            self.cand = None
            self._test(w, j, r0, var)
        else:  # a disturbed field, or the magnetic situation changed: a candidate learns from the rejected windows
            self.rejected += 1
            if self.test.holds or not self._retest(w, j, r0, var):
                self._candidate(j, r0, ws)
        self._cache()
        self.changes.window(self.trusted != trusted or not (trusted or self.est is est), (self._a, self._c),
                            self.m_last, self.q)
        self._set_state()

    def _test(self, w: Window, j: Array, r0: Array, var: float) -> None:
        """The prior's test (:mod:`.hypothesis`) after a window the estimate took; once rejected, such a window that
        contradicts the prior too ends the windows that would restore it (one both explain is evidence for neither)."""
        if self.test.holds:
            self.test.add(self.est, j, r0, var, self._tolerance(w))
        elif self.test.window_fails(j, r0, var, self._tolerance(w)):
            self.agree = 0

    def _tolerance(self, w: Window) -> Array:
        return self.test.tolerance_at(np.asarray(w.m1_ut), self.q)

    def _retest(self, w: Window, j: Array, r0: Array, var: float) -> bool:
        """After the prior was rejected, a window the estimate rejected: :data:`~.records.SWITCH_WINDOWS` such windows
        that agree with the prior, none failing it between them, restore it (a magnet attached for a while and taken
        off again); the estimate and the test start anew from the prior. A window that agrees with both (observing
        none of their difference) is evidence for neither (:meth:`_test`). Returns whether it agreed with the prior."""
        if self.test.window_fails(j, r0, var, self._tolerance(w)):
            self.agree = 0
            return False
        self.agree += 1
        if self.agree >= SWITCH_WINDOWS:
            self.est, self.cand = InfoEstimate(self.model, self.lam0, self.theta0), None
            self.test = PriorTest(self.model, self.theta0)
            self.windows, self.agree = 0, 0
        return True

    @property
    def trusted(self) -> bool:
        """The readings get the prior as configured: it holds, as the more probable hypothesis (else: the estimate)."""
        return self.test.holds and self.test.p_holds >= 0.5

    def _candidate(self, j: Array, r0: Array, ws: WindowSet) -> None:
        """A rejected window goes to the candidate (restarted from the prior when it does not fit the candidate
        either); :data:`~.records.SWITCH_WINDOWS` consecutive rejected windows that fit one candidate replace the
        estimate with it."""
        cand = self.cand
        if cand is not None:
            var = float(self.model.window_var(ws, self.model.soft_iron(cand.theta), cand.theta[self.model.p:])[0])
            d2, k = cand.window(j, r0, var)
            if not cand.passes(d2):
                cand = None
        if cand is None:
            cand = InfoEstimate(self.model, self.lam0, self.theta0)
            var = float(self.model.window_var(ws, self.model.soft_iron(cand.theta), cand.theta[self.model.p:])[0])
            d2, k = cand.window(j, r0, var)
        cand.add(j, r0, var, d2, k)
        self.cand = cand
        if cand.added >= SWITCH_WINDOWS:
            self.est, self.cand = cand, None
            self.windows = cand.added
            self.switches += 1

    @property
    def theta(self) -> Array:
        """The estimate θ (:mod:`.model`)."""
        return self.est.theta

    @property
    def unit_weight(self) -> float:
        """The current estimate's variance of unit weight (:class:`~.solver.InfoEstimate`)."""
        return self.est.unit_weight

    @property
    def covariance(self) -> Array:
        """The covariance of the calibration in use (:attr:`in_use`): a saved prior's while it is used, else ``Λ⁻¹``
        scaled up by the variance of unit weight above 1; with the hard iron's floor (``SYSTEMATIC_SD_UT``)."""
        if self.trusted and self.test.saved is not None:
            return self.model.with_floor(self.test.saved)
        return self.model.with_floor(self.est.cov * max(1.0, self.unit_weight))

    @property
    def in_use(self) -> Array:
        """The calibration the state and the saved file describe: a saved prior while it is used, else the estimate."""
        return self.theta0 if self.trusted and self.test.saved is not None else self.theta

    def _cache(self) -> None:
        theta = self.theta0 if self.trusted else self.theta  # the calibration the readings get
        a = self.model.soft_iron(theta)
        self._a = tuple(float(v) for v in a.reshape(9))
        self._c = tuple(float(v) for v in theta[self.model.p:])
        est_a = self.model.soft_iron(self.theta)  # the estimate's own (the same once the prior is rejected)
        self._est_a = tuple(float(v) for v in est_a.reshape(9))
        self._est_c = tuple(float(v) for v in self.theta[self.model.p:])
        self.q_refresh = None  # refresh the field covariance at the next heading σ

    def _maybe_refresh(self) -> None:
        qr, qw = self.q_refresh, self.windower.q
        if qr is not None and abs(qr[0] * qw[0] + qr[1] * qw[1] + qr[2] * qw[2] + qr[3] * qw[3]) >= _COS_REFRESH:
            return
        self.q_refresh = qw
        m = np.asarray(self.m_last if self.m_last is not None else (0.0, 0.0, 0.0), dtype=float)
        su = self.model.field_covariance(m, self.covariance)
        self.su = tuple(float(su[i, j]) for i, j in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)))
        self.field_sd_ut = math.sqrt(max(float(np.linalg.eigvalsh(su)[-1]), 0.0))

    def _set_state(self) -> None:
        if self.m_last is None:
            self.bound = math.pi
        elif self.q is None:  # no attitude: the worst direction in the sensor frame, ignoring the dip
            m = np.asarray(self.m_last)
            su = self.model.field_covariance(m, self.covariance)
            u = np.asarray(self._a).reshape(3, 3) @ m - np.asarray(self._c)
            self.bound = math.sqrt(float(np.linalg.eigvalsh(su)[-1])) / max(float(np.linalg.norm(u)), 1e-9)
        else:
            u = np.asarray(self._a).reshape(3, 3) @ np.asarray(self.m_last) - np.asarray(self._c)
            self.bound = heading_sd_bound(self.model, self.in_use, self.covariance, self.q, u, STATE_HEADINGS)
        if self.bound <= CALIBRATED_SD_RAD:
            self.state = CALIBRATED
            if self.converged_after_s is None:
                self.converged_after_s = self.windower.t
        else:
            self.state = UNCALIBRATED if self.windows == 0 else CONVERGING

    # -------------------------------------------------------------------------------------------------- outputs
    def calibration(self) -> MagCalibration:
        """The calibration :attr:`in_use` as a record (for the saved file and the node)."""
        return _record(self)

    def status(self) -> MagCalStatus:
        """The diagnostics record (module docstring)."""
        cal = self.calibration()
        return MagCalStatus(state=self.state, hard_iron_t=cal.hard_iron_t, hard_iron_sd_t=cal.hard_iron_sd_t,
                            heading_sd_bound_rad=self.bound, windows=self.windows, rejected=self.rejected,
                            unit_weight=self.unit_weight, converged_after_s=self.converged_after_s,
                            prior_holds=self.trusted)


def _record(cal: OnlineMagCalibrator) -> MagCalibration:
    """:meth:`OnlineMagCalibrator.calibration`."""
    theta = cal.in_use
    a, h = cal.model.split(theta)
    cov = cal.model.output_covariance(theta, cal.covariance)
    scale = np.r_[np.ones(9), np.full(3, UT)]
    cov = cov * np.outer(scale, scale)
    return MagCalibration(hard_iron_t=tuple(float(v) * UT for v in h),  # type: ignore[arg-type]
                          soft_iron=tuple(float(v) for v in a.reshape(9)),
                          covariance=tuple(float(v) for v in cov.reshape(144)), state=cal.state,
                          windows=cal.windows, converged_after_s=cal.converged_after_s,
                          soft_iron_model=cal.model.model)
