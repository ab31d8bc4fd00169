"""What a window decides in the online calibration (ROS-free): the prior's test after a window the estimate took,
the restore of a rejected prior, and the candidate that replaces the estimate when the magnetic situation changed.

Each function takes the calibrator (:class:`~.online.OnlineMagCalibrator`) and changes its state record
(:class:`~.calstate.CalibratorState`); :meth:`~.online.OnlineMagCalibrator._add_window` calls them once per window.
"""

from __future__ import annotations

import numpy as np

from riann_ros.magcal.calstate import Calibrator
from riann_ros.magcal.hypothesis import PriorTest
from riann_ros.magcal.model import Array
from riann_ros.magcal.records import SWITCH_WINDOWS
from riann_ros.magcal.solver import InfoEstimate
from riann_ros.magcal.windows import Window, WindowSet


def test_prior(cal: Calibrator, w: Window, j: Array, r0: Array, var: float) -> None:
    """The prior's test (:mod:`.hypothesis`) after a window the estimate took; once rejected, such a window that
    contradicts the prior too ends the windows that would restore it (one both explain is evidence for neither)."""
    s = cal.s
    if s.test.holds:
        s.test.add(s.est, j, r0, var, _tolerance(cal, w))
    elif s.test.window_fails(j, r0, var, _tolerance(cal, w)):
        s.agree = 0


def _tolerance(cal: Calibrator, w: Window) -> Array:
    return cal.s.test.tolerance_at(np.asarray(w.m1_ut), cal.s.q)


def retest_prior(cal: Calibrator, w: Window, j: Array, r0: Array, var: float) -> bool:
    """After the prior was rejected, a window the estimate rejected: :data:`~.records.SWITCH_WINDOWS` such windows
    that agree with the prior, none failing it between them, restore it (a magnet attached for a while and taken off
    again); the estimate and the test start anew from the prior. A window that agrees with both (observing none of
    their difference) is evidence for neither (:func:`test_prior`). Returns whether it agreed with the prior."""
    s = cal.s
    if s.test.window_fails(j, r0, var, _tolerance(cal, w)):
        s.agree = 0
        return False
    s.agree += 1
    if s.agree >= SWITCH_WINDOWS:
        s.est, s.cand = InfoEstimate(cal.model, cal.lam0, cal.theta0), None
        s.test = PriorTest(cal.model, cal.theta0)
        s.windows, s.agree = 0, 0
    return True


def candidate(cal: Calibrator, j: Array, r0: Array, ws: WindowSet) -> None:
    """A rejected window goes to the candidate (restarted from the prior when it does not fit the candidate either);
    :data:`~.records.SWITCH_WINDOWS` consecutive rejected windows that fit one candidate replace the estimate with
    it."""
    s, model = cal.s, cal.model
    cand = s.cand
    if cand is not None:
        var = float(model.window_var(ws, model.soft_iron(cand.theta), cand.theta[model.p:])[0])
        d2, k = cand.window(j, r0, var)
        if not cand.passes(d2):
            cand = None
    if cand is None:
        cand = InfoEstimate(model, cal.lam0, cal.theta0)
        var = float(model.window_var(ws, model.soft_iron(cand.theta), cand.theta[model.p:])[0])
        d2, k = cand.window(j, r0, var)
    cand.add(j, r0, var, d2, k)
    s.cand = cand
    if cand.added >= SWITCH_WINDOWS:
        s.est, s.cand = cand, None
        s.windows = cand.added
        s.switches += 1
