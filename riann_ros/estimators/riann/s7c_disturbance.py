"""Stage 7c, the magnetic disturbance test of the heading: the field's norm and dip against a reference learned online
(VQF's rules and constants; ROS-free).

Per sample with a field (:func:`disturbance`): the norm and the dip are low-passed (:data:`CURRENT_TAU`) and compared
with the reference (bands :data:`NORM_TH` of the norm and :data:`DIP_TH`, widened while the online calibration
converges). While they stay in the bands the reference follows them slowly (:data:`REF_TAU`) and the field is
undisturbed after :data:`MIN_UNDISTURBED`; outside, the field is disturbed and the heading follows the gyro only
(for :data:`MAX_REJECT`, then the gain is divided by :data:`REJECT_FACTOR`). A new field steady for :data:`NEW_TIME`
of motion becomes the reference. During the heading's start the reference is the running mean of the fields (assumed
undisturbed). The whole state is :class:`ReferenceState`, part of the heading's record (:mod:`.s7a_mag`).
"""

from __future__ import annotations

from dataclasses import dataclass

from riann_ros.constants import DEG

# VQF's defaults (vqf 2.1.2 VQFParams): magnetic disturbance rejection
NORM_TH = 0.1  # relative deviation of |m| from the reference
DIP_TH = 10.0 * DEG  # deviation of the dip angle from the reference
CURRENT_TAU = 0.05  # s, low-pass of |m| and dip before the test
REF_TAU = 20.0  # s, the reference follows the undisturbed field with this time constant
MIN_UNDISTURBED = 0.5  # s in the band before the field is trusted again
MAX_REJECT = 60.0  # s of full rejection, then the gain is divided by REJECT_FACTOR
REJECT_FACTOR = 2.0
NEW_TIME = 20.0  # s of a stable new field (while moving) before it becomes the reference
NEW_MIN_GYR = 20.0 * DEG  # rad/s, only motion faster than this counts toward NEW_TIME


@dataclass
class ReferenceState:
    """The disturbance test's state: the low-passed norm (T) and dip (rad), the reference and the candidate for a new
    one, the times (s) the candidate has been steady in motion, the field in the bands, and the field rejected, and
    whether the field is disturbed."""

    norm_lp: float = 0.0
    dip_lp: float = 0.0
    ref_norm: float = 0.0
    ref_dip: float = 0.0
    cand_norm: float = 0.0
    cand_dip: float = 0.0
    cand_t: float = 0.0
    undist_t: float = 0.0
    reject_t: float = 0.0
    disturbed: bool = False

    def begin(self, norm: float, dip: float) -> None:
        """The first field sets the low-passes, the reference and the candidate."""
        self.norm_lp = self.ref_norm = self.cand_norm = norm
        self.dip_lp = self.ref_dip = self.cand_dip = dip

    def fits(self, norm: float, dip: float) -> bool:
        """The field (norm T, dip rad) is within the reference's bands (those of a calibrated field)."""
        return abs(norm - self.ref_norm) < NORM_TH * self.ref_norm and abs(dip - self.ref_dip) < DIP_TH


def disturbance(r: ReferenceState, n: float, dip: float, dt: float, k: float, start: int, band: float,
                gyr_lp: float) -> float:
    """The test on one field (norm ``n`` T, ``dip`` rad, step ``dt`` s): the gain to use for this sample, ``k`` the
    heading's gain without a disturbance; ``start`` the count of the start's fields while the heading starts (0 after
    it: the reference is then learned as their running mean), ``band`` T by which the bands widen (the calibrated
    field's doubt), ``gyr_lp`` the low-passed rate (rad/s)."""
    c = dt / (CURRENT_TAU + dt)
    r.norm_lp += c * (n - r.norm_lp)
    r.dip_lp += c * (dip - r.dip_lp)
    n, dip = r.norm_lp, r.dip_lp
    k_ref = dt / REF_TAU
    if start:  # the reference is the running mean of the start (assumed undisturbed)
        kr = max(k_ref, 1.0 / start)
        r.ref_norm += kr * (n - r.ref_norm)
        r.ref_dip += kr * (dip - r.ref_dip)
        r.cand_norm, r.cand_dip = r.ref_norm, r.ref_dip
        return k
    if abs(n - r.ref_norm) < NORM_TH * r.ref_norm + band and abs(dip - r.ref_dip) < DIP_TH + band / n:
        r.undist_t += dt
        if r.undist_t >= MIN_UNDISTURBED:
            r.disturbed = False
            r.ref_norm += k_ref * (n - r.ref_norm)
            r.ref_dip += k_ref * (dip - r.ref_dip)
    else:
        r.undist_t = 0.0
        r.disturbed = True
    _new_field(r, n, dip, dt, k_ref, gyr_lp)
    if r.disturbed:
        if r.reject_t <= MAX_REJECT:
            r.reject_t += dt
            return 0.0
        return k / REJECT_FACTOR
    r.reject_t = max(r.reject_t - REJECT_FACTOR * dt, 0.0)
    return k


def _new_field(r: ReferenceState, n: float, dip: float, dt: float, k_ref: float, gyr_lp: float) -> None:
    """A new stable field (norm and dip steady while moving for NEW_TIME) becomes the reference."""
    if abs(n - r.cand_norm) < NORM_TH * r.cand_norm and abs(dip - r.cand_dip) < DIP_TH:
        if gyr_lp >= NEW_MIN_GYR:
            r.cand_t += dt
        r.cand_norm += k_ref * (n - r.cand_norm)
        r.cand_dip += k_ref * (dip - r.cand_dip)
        if r.disturbed and r.cand_t >= NEW_TIME:
            r.ref_norm, r.ref_dip = r.cand_norm, r.cand_dip
            r.disturbed = False
            r.undist_t = MIN_UNDISTURBED
    else:
        r.cand_t = 0.0
        r.cand_norm, r.cand_dip = n, dip
