"""What the online calibration knows, as the σ it adds to a heading and to the field (ROS-free).

``Λ⁻¹`` (times the variance of unit weight when the windows scatter more than the noise model says) is the
estimate's covariance (:attr:`~.online.OnlineMagCalibrator.covariance`). :func:`heading_sd_rad` turns it into the σ
it adds to a tilt-compensated heading for the current attitude and field, per sample, through a cached 3×3 field
covariance refreshed every :data:`~.records.REFRESH_ANGLE_RAD` of rotation (:func:`refresh`); :func:`field_sd_t`
the calibrated field's own σ; :func:`state_bound` the largest heading σ over all headings at the current tilt, which
decides the calibrator's state. While the configured calibration is used (:attr:`~.online.OnlineMagCalibrator.trusted`)
the heading σ is the share of the doubt the gyro-aided test leaves about it (:mod:`.hypothesis`).
"""

from __future__ import annotations

import math

import numpy as np

from riann_ros.magcal.calstate import Calibrator
from riann_ros.magcal.heading import heading_gap
from riann_ros.magcal.model import heading_sd_bound
from riann_ros.magcal.records import REFRESH_ANGLE_RAD, STATE_HEADINGS, UT
from riann_ros.rotations import Quat, Vec, rotate

_COS_REFRESH = math.cos(0.5 * REFRESH_ANGLE_RAD)
#: below this posterior probability that the configured calibration is wrong, its share of the heading σ is none (a
#: millionth of even a 180° doubt is 0.2°: below the field heading's own σ, 2.5°, in quadrature: 0.006°)
UNDOUBTED = 1e-6


def heading_sd_rad(cal: Calibrator, q: Quat, field_world_t: Vec) -> float:
    """rad; the σ the calibration adds to the heading of this sample (``q`` its attitude, sensor → world;
    ``field_world_t`` its calibrated field, world frame, T): π with a vertical field, and while the last window
    contradicted the estimate (disturbed, or a changed magnetic situation). While the prior is used, the mixture of
    the two hypotheses (:mod:`.hypothesis`): ``σ² = p σ₀² + (1 − p)(σ₁² + Δ²)``, ``p`` the probability that the prior
    holds (0 once the test rejected it: the prior used as a monitor), ``σ₀`` the heading σ of a saved prior's own
    covariance (0 for a configured one: it is right to within the field heading's σ, which the estimators add), ``σ₁``
    the estimate's and ``Δ`` the heading difference between the two."""
    s = cal.s
    trusted = cal.trusted
    test = s.test
    doubt = (1.0 - test.p_holds if test.holds else 1.0) if trusted else 1.0
    saved = trusted and test.saved is not None
    if doubt < UNDOUBTED and not saved:
        return 0.0
    fx, fy = field_world_t[0], field_world_t[1]
    fh = math.sqrt(fx * fx + fy * fy)
    if fh <= 0.0:
        return math.pi
    if trusted:  # the field calibrated as configured: the mixture's share (riann_ros.magcal.hypothesis)
        s1 = _heading_sd(cal, q, fx / fh, fy / fh, fh)
        ap = s.applied
        d = 0.0 if s.m_last is None else heading_gap(ap.est_a, ap.est_c, s.m_last, q, field_world_t)
        s0 = _heading_sd(cal, q, fx / fh, fy / fh, fh, s.sd.su0) if saved else 0.0
        return min(math.sqrt((1.0 - doubt) * s0 * s0 + doubt * (s1 * s1 + d * d)), math.pi)
    if s.cand is not None:  # the last window contradicted the estimate: disturbed, or the situation changed
        return math.pi
    return _heading_sd(cal, q, fx / fh, fy / fh, fh)


def _heading_sd(cal: Calibrator, q: Quat, ex: float, ey: float, fh: float,
                su: tuple[float, ...] | None = None) -> float:
    """rad; the heading σ for the horizontal field direction (ex, ey) of strength ``fh`` (T) from the field covariance
    ``su`` (default: the estimate's)."""
    refresh(cal)
    wx, wy, wz = rotate((q[0], -q[1], -q[2], -q[3]), (ey, -ex, 0.0))  # across the field, sensor frame
    s = cal.s.sd.su if su is None else su
    var = (s[0] * wx * wx + s[3] * wy * wy + s[5] * wz * wz
           + 2.0 * (s[1] * wx * wy + s[2] * wx * wz + s[4] * wy * wz))
    return math.sqrt(max(var, 0.0)) * UT / fh


def field_sd_t(cal: Calibrator) -> float:
    """T; the calibrated field's σ in its worst direction for the current orientation: how far its norm and dip can
    be off through the calibration alone (a disturbance test against a learned reference should widen its band by a
    few of these while the calibration converges); 0 while the prior holds."""
    if cal.trusted:
        return 0.0
    refresh(cal)
    return cal.s.sd.field_sd_ut * UT


def refresh(cal: Calibrator) -> None:
    """The cached field covariance anew once the sensor has turned :data:`~.records.REFRESH_ANGLE_RAD` since it was
    computed (or it was made stale)."""
    s = cal.s
    qr, qw = s.sd.q_refresh, s.windower.q
    if qr is not None and abs(qr[0] * qw[0] + qr[1] * qw[1] + qr[2] * qw[2] + qr[3] * qw[3]) >= _COS_REFRESH:
        return
    s.sd.q_refresh = qw
    m = np.asarray(s.m_last if s.m_last is not None else (0.0, 0.0, 0.0), dtype=float)
    su = cal.model.field_covariance(m, cal.h1_covariance)
    s.sd.su = _upper(su)
    s.sd.field_sd_ut = math.sqrt(max(float(np.linalg.eigvalsh(su)[-1]), 0.0))
    if s.test.saved is not None:
        s.sd.su0 = _upper(cal.model.field_covariance(m, saved_covariance(cal)))


def saved_covariance(cal: Calibrator) -> np.ndarray:
    """A saved calibration's covariance as this run knows it while it holds: the file's (its fit, widened by how far
    a hard iron moves between runs, :meth:`~.records.MagCalPrior.from_calibration`) fused with what this run's
    windows say, ``S − S (S + C₁)⁻¹ S`` (``C₁`` the estimate's covariance, :attr:`h1_covariance`: the windows'
    information; the broad prior it also holds is orders of magnitude weaker); with the hard iron's floor. At the start
    it is the file's; as the windows confirm the file it narrows to what they add."""
    saved = cal.s.test.saved
    assert saved is not None
    c1 = cal.h1_covariance
    fused = saved - saved @ np.linalg.solve(saved + c1, saved)
    return cal.model.with_floor(0.5 * (fused + fused.T))


def _upper(su: np.ndarray) -> tuple[float, ...]:
    """The six numbers of a symmetric 3×3 (xx, xy, xz, yy, yz, zz)."""
    return tuple(float(su[i, j]) for i, j in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)))


def state_bound(cal: Calibrator) -> float:
    """rad; the largest heading σ the calibration can add over all headings at the current tilt (π before a reading;
    without an attitude, the worst direction in the sensor frame, ignoring the dip)."""
    s = cal.s
    if s.m_last is None:
        return math.pi
    u = np.asarray(s.applied.a).reshape(3, 3) @ np.asarray(s.m_last) - np.asarray(s.applied.c)
    if s.q is None:
        su = cal.model.field_covariance(np.asarray(s.m_last), cal.covariance)
        return math.sqrt(float(np.linalg.eigvalsh(su)[-1])) / max(float(np.linalg.norm(u)), 1e-9)
    return heading_sd_bound(cal.model, cal.in_use, cal.covariance, s.q, u, STATE_HEADINGS)
