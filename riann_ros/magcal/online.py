"""The online calibration: causal, per sample, gyro-aided (ROS-free).

Per sample (:meth:`OnlineMagCalibrator.update`, plain floats): the gyro increment goes into the open window (one
quaternion product), the reading is calibrated with the current estimate (a 3×3 product). Once per window (numpy,
:meth:`OnlineMagCalibrator._add_window`): the window's innovation is tested against its covariance (the window's
noise plus the estimate's own uncertainty, scaled by the variance of unit weight) and, if it passes, added to the
information-form least squares ``(Λ, η)`` that started from the prior; ``θ = Λ⁻¹ η``, with the windows' information
kept only in the directions they know at least as well as the prior (:func:`~.model.posterior`). Without rotation
no window closes, so the estimate holds at rest and in straight motion; a rotation about one axis only informs what
that rotation observes (the prior keeps the rest). Nothing is forgotten: no drift.

What it knows (:mod:`.knowledge`): ``Λ⁻¹`` (times the variance of unit weight when the windows scatter more than the
noise model says) is the estimate's covariance; :meth:`heading_sd_rad` turns it into the σ it adds to a
tilt-compensated heading for the current attitude and field, per sample. The state is *calibrated* once the largest
such σ over all headings at the current tilt is at most :data:`~.records.CALIBRATED_SD_RAD`, *uncalibrated* while no
window has been added, *converging* in between.

The prior as a hypothesis (:mod:`.hypothesis`): while the windows are consistent with the configured (or saved)
calibration and make it the more probable hypothesis, the readings are calibrated with it as it is and
:meth:`heading_sd_rad` adds only the doubt they leave (:attr:`trusted`); otherwise with the estimate and its σ, for
good once the test rejects the prior.

Everything it changes is one record, :class:`~.calstate.CalibratorState` (:attr:`OnlineMagCalibrator.s`;
:meth:`OnlineMagCalibrator.snapshot` and :meth:`OnlineMagCalibrator.restore`).
"""

from __future__ import annotations

import copy
import dataclasses

import numpy as np

from riann_ros.magcal import decisions, knowledge
from riann_ros.magcal.calstate import Applied, CalibratorState
from riann_ros.magcal.changes import Changes
from riann_ros.magcal.hypothesis import PriorTest
from riann_ros.magcal.model import Array, CalModel
from riann_ros.magcal.records import (
    CALIBRATED,
    CALIBRATED_SD_RAD,
    CONVERGING,
    DELAY_SD_S,
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
from riann_ros.rotations import Quat, Vec

_MIN2_UT, _MAX2_UT = (USABLE_MIN_T / UT) ** 2, (USABLE_MAX_T / UT) ** 2  # µT²: the input's plausible norms


class OnlineMagCalibrator:
    """The online calibration (module docstring). ``prior``: the configured or saved calibration;
    ``soft_iron_model``: ``full`` (default: all 3×3 including the magnetometer's misalignment to the gyro, which
    the gyro-aided constraint observes), ``symmetric`` or ``none`` (hard iron only); ``fixed``: the readings always
    get the prior, the estimate and the test run beside it (``mag_calibration`` off: the test as a monitor)."""

    def __init__(self, prior: MagCalPrior | None = None, soft_iron_model: SoftIronModel = "full",
                 fixed: bool = False) -> None:
        prior = prior or MagCalPrior()
        self.fixed = fixed
        self.model = CalModel(soft_iron_model, np.asarray(prior.soft_iron).reshape(3, 3))
        self.lam0, self.theta0 = self.model.prior(dataclasses.replace(prior, covariance=None))  # the estimate's: broad
        saved = None if prior.covariance is None else np.linalg.inv(self.model.prior(prior)[0])  # a saved one's σ
        est = InfoEstimate(self.model, self.lam0, self.theta0)
        test = PriorTest(self.model, self.theta0, saved)
        applied = self._applied(est, test)
        self.s = CalibratorState(est=est, test=test, windower=Windower(), windows=prior.windows, applied=applied,
                                 changes=Changes((applied.a, applied.c)))
        self._set_state()

    def snapshot(self) -> CalibratorState:
        """The whole state (:class:`~.calstate.CalibratorState`), independent of this calibrator."""
        return copy.deepcopy(self.s)

    def restore(self, state: CalibratorState) -> None:
        """Back to a :meth:`snapshot` (of a calibrator built from the same prior)."""
        self.s = copy.deepcopy(state)

    # -------------------------------------------------------------------------------------------------- per sample
    def update(self, delta: Quat, dt: float, mag_t: Vec | None, delay_s: float = 0.0, q: Quat | None = None,
               delay_sd_s: float = DELAY_SD_S) -> Vec | None:
        """One sample: ``delta`` the bias-corrected gyro increment (sensor frame), ``dt`` its step (s), ``mag_t``
        the raw field (T; a reading that is not finite or outside the input's plausible 1 µT–1 mT counts as none) or
        None, ``delay_s`` the magnetometer's latency (s) and ``delay_sd_s`` its standard deviation, ``q`` the
        attitude (sensor → world; only its tilt matters) when known. Returns the calibrated field (T) or None."""
        s = self.s
        if q is not None:
            s.q = q
        m = None
        if mag_t is not None:
            m = (mag_t[0] / UT, mag_t[1] / UT, mag_t[2] / UT)
            n2 = m[0] * m[0] + m[1] * m[1] + m[2] * m[2]
            if not _MIN2_UT <= n2 <= _MAX2_UT:  # not finite (NaN fails too), dead or saturated: no reading
                m = None
        w = s.windower.add(delta, dt, m, delay_s, delay_sd_s)
        if w is not None:
            self._add_window(w)
        if m is None:
            return None
        first = s.m_last is None
        s.m_last = m
        if first:
            self._set_state()
        a, c = s.applied.a, s.applied.c
        x, y, z = m
        return ((a[0] * x + a[1] * y + a[2] * z - c[0]) * UT, (a[3] * x + a[4] * y + a[5] * z - c[1]) * UT,
                (a[6] * x + a[7] * y + a[8] * z - c[2]) * UT)

    def restart(self) -> None:
        """A hole in the gyro stream: the open window is dropped; the estimate is kept."""
        self.s.windower.restart()

    def heading_sd_rad(self, q: Quat, field_world_t: Vec) -> float:
        """rad; the σ the calibration adds to the heading of this sample (:func:`.knowledge.heading_sd_rad`)."""
        return knowledge.heading_sd_rad(self, q, field_world_t)

    def field_sd_t(self) -> float:
        """T; the calibrated field's σ in its worst direction (:func:`.knowledge.field_sd_t`)."""
        return knowledge.field_sd_t(self)

    # -------------------------------------------------------------------------------------------------- per window
    def _add_window(self, w: Window) -> None:
        s = self.s
        ws = WindowSet.of([w])
        jw, rw = self.model.rows(ws)
        j, r0 = jw[0], rw[0]
        est = s.est
        trusted = self.trusted
        var = float(self.model.window_var(ws, self.model.soft_iron(est.theta), est.theta[self.model.p:])[0])
        d2, k = est.window(j, r0, var)
        if est.passes(d2):
            est.add(j, r0, var, d2, k)
            s.windows += 1
            s.cand = None
            decisions.test_prior(self, w, j, r0, var)
        else:  # a disturbed field, or the magnetic situation changed: a candidate learns from the rejected windows
            s.rejected += 1
            if s.test.holds or not decisions.retest_prior(self, w, j, r0, var):
                decisions.candidate(self, j, r0, ws)
        s.applied = self._applied(s.est, s.test)
        s.sd.q_refresh = None  # refresh the field covariance at the next heading σ
        s.changes.window(self.trusted != trusted or not (trusted or s.est is est), (s.applied.a, s.applied.c),
                         s.m_last, s.q)
        self._set_state()

    def _applied(self, est: InfoEstimate, test: PriorTest) -> Applied:
        """The calibration the readings get (the prior while it is trusted, else the estimate) and the estimate's
        own, in plain floats."""
        theta = self.theta0 if self.fixed or (test.holds and test.p_holds >= 0.5) else est.theta
        p = self.model.p
        return Applied(tuple(float(v) for v in self.model.soft_iron(theta).reshape(9)),
                       tuple(float(v) for v in theta[p:]),
                       tuple(float(v) for v in self.model.soft_iron(est.theta).reshape(9)),
                       tuple(float(v) for v in est.theta[p:]))

    def _set_state(self) -> None:
        s = self.s
        s.bound = knowledge.state_bound(self)
        if s.bound <= CALIBRATED_SD_RAD:
            s.state = CALIBRATED
            if s.converged_after_s is None:
                s.converged_after_s = s.windower.t
        else:
            s.state = UNCALIBRATED if s.windows == 0 else CONVERGING

    # -------------------------------------------------------------------------------------------------- readouts
    @property
    def trusted(self) -> bool:
        """The readings get the prior as configured: it holds, as the more probable hypothesis (else: the estimate);
        always when :attr:`fixed`."""
        return self.fixed or (self.s.test.holds and self.s.test.p_holds >= 0.5)

    @property
    def test(self) -> PriorTest:
        """The prior's test (:mod:`.hypothesis`)."""
        return self.s.test

    @property
    def changes(self) -> Changes:
        """What a filter's heading built on the field must follow (:mod:`.changes`)."""
        return self.s.changes

    @property
    def windows(self) -> int:
        """Windows in the information (a saved calibration's included)."""
        return self.s.windows

    @property
    def rejected(self) -> int:
        """Windows rejected as disturbed in this run."""
        return self.s.rejected

    @property
    def state(self) -> CalState:
        return self.s.state

    @property
    def converged_after_s(self) -> float | None:
        """s after this run's first sample at which the state was first *calibrated* (None: not yet)."""
        return self.s.converged_after_s

    @property
    def theta(self) -> Array:
        """The estimate θ (:mod:`.model`)."""
        return self.s.est.theta

    @property
    def unit_weight(self) -> float:
        """The current estimate's variance of unit weight (:class:`~.solver.InfoEstimate`)."""
        return self.s.est.unit_weight

    @property
    def covariance(self) -> Array:
        """The covariance of the calibration in use (:attr:`in_use`): a saved prior's while it is used (as this run's
        windows confirm it, :func:`.knowledge.saved_covariance`), else ``Λ⁻¹`` scaled up by the variance of unit weight
        above 1; with the hard iron's floor (``SYSTEMATIC_SD_UT``)."""
        if self.trusted and self.s.test.saved is not None:
            return knowledge.saved_covariance(self)
        return self.h1_covariance

    @property
    def h1_covariance(self) -> Array:
        """The estimate's covariance (``H₁``'s: the calibration as the windows alone know it), ``Λ⁻¹`` scaled up by the
        variance of unit weight above 1, with the hard iron's floor."""
        return self.model.with_floor(self.s.est.cov * max(1.0, self.unit_weight))

    @property
    def in_use(self) -> Array:
        """The calibration the state and the saved file describe: a saved prior while it is used (and the prior while
        :attr:`fixed`), else the estimate."""
        return self.theta0 if self.fixed or (self.trusted and self.s.test.saved is not None) else self.theta

    # -------------------------------------------------------------------------------------------------- outputs
    def calibration(self) -> MagCalibration:
        """The calibration :attr:`in_use` as a record (for the saved file and the node)."""
        return _record(self)

    def status(self) -> MagCalStatus:
        """The diagnostics record (module docstring)."""
        cal = self.calibration()
        return MagCalStatus(state=self.state, hard_iron_t=cal.hard_iron_t, hard_iron_sd_t=cal.hard_iron_sd_t,
                            heading_sd_bound_rad=self.s.bound, windows=self.windows, rejected=self.rejected,
                            unit_weight=self.unit_weight, converged_after_s=self.converged_after_s,
                            prior_holds=self.trusted)


def _record(cal: OnlineMagCalibrator) -> MagCalibration:
    """The calibration ``cal`` uses (:attr:`OnlineMagCalibrator.in_use`) as a record: ``S``, ``h`` in T and their
    covariance in the record's units."""
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
