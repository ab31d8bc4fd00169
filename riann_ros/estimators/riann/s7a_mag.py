"""Stage 7a, the magnetic heading: a heading-only correction toward the field, with disturbance rejection (ROS-free).

Per sample with a field (:meth:`MagHeading.step`): the field is rotated back by the gyro over the magnetometer's
latency (stage 7b), tilt-compensated with the output attitude (``m_w = R(q) m``; heading error
``atan2(m_w,x, m_w,y)``, zero when the horizontal field points along +y, magnetic north in ENU), tested for
disturbance against a reference norm and dip learned online (VQF's rules and constants: then the heading follows
the gyro only), and the heading moves toward it with the gain ``dt / tau_mag`` (the running mean during the first
``tau_mag`` seconds). After a hole (:meth:`MagHeading.reacquire`; not while the field is rejected) it re-converges
as the inverse-variance weighted mean of the bridged heading and each field heading since, a field weighing less
while the inclination is uncertain (``1 / (σ_w² + tan²(dip) σ_t²)``, ``σ_w`` = :data:`REACQUIRE_FIELD_SD_DEG`, a
weight of its own: stage 8 reports the fitted field σ, :data:`~riann_ros.defaults.MAG_HEADING_SD_DEG`). The
correction is a rotation about the world vertical: the inclination is never changed by the field.

With the online calibration (:attr:`MagHeading.cal`, :mod:`riann_ros.magcal`) the raw field goes to it first, and
all of the above sees the calibrated field. While the configured calibration is used (it holds the gyro-aided test,
:mod:`riann_ros.magcal.hypothesis`, as the more probable hypothesis) nothing else changes. Once the estimate is used
instead the heading starts over from the next field (the one it has was set by a field calibrated otherwise), and
each field heading counts as much as the calibration knows it: its weight is ``1/(σ_m² + σ_c²)`` (``σ_c`` the
heading σ the calibration adds at this sample, ``σ_m`` the field heading's own, stage 8's MAG_SD): the gain is
``dt/tau_mag · σ_m²/(σ_m² + σ_c²)``, and the start's inverse-variance mean stays open while ``σ_c > σ_m``; the
disturbance test widens its norm and dip bands by three of the calibrated field's σ. While the configured
calibration is used its gains are the usual ones: no other source of heading exists that the field could be weighed
against (the gyro's heading came from the same field); the doubt the windows leave about it goes to stage 8's σ
(:attr:`MagHeading.doubt_sd`). docs/magnetometer.md has the physics.
"""

from __future__ import annotations

import math

from riann_ros.constants import DEG
from riann_ros.defaults import MAG_HEADING_SD_DEG
from riann_ros.magcal.frontend import MagFrontEnd
from riann_ros.magcal.heading import heading_angle
from riann_ros.magcal.records import GYRO_BIAS_RESIDUAL_SD_RAD_S
from riann_ros.rotations import Quat, Vec, rotate, to_rotvec

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
GYR_LP_TAU = 0.5  # s, low-pass of |ω| for NEW_MIN_GYR
# re-acquiring after a hole
#: deg; the σ a field heading is weighed with against the bridged heading (and the fields before it) while the
#: heading re-acquires after a hole: a weight that sets how fast the heading leaves the bridge for the fields. It is
#: not the field heading's σ that stage 8 reports (MAG_HEADING_SD_DEG, fitted on BROAD); that one would weigh the
#: first fields after a hole four times as much
REACQUIRE_FIELD_SD_DEG = 5.0
BRIDGE_GATE = 3.0  # the bridge is dropped if the first field after the hole is this many standard deviations off
MAG_SD = MAG_HEADING_SD_DEG * DEG  # rad; a calibrated field heading's σ (stage 8's): a calibration's σ weighs on it
CAL_BAND = 3.0  # the disturbance bands widen by this many of the calibrated field's σ while it converges


class MagHeading:
    """The heading correction state (see the module docstring); :meth:`step` per sample."""

    def __init__(self, tau_mag: float, reject: bool, front: MagFrontEnd) -> None:
        self.configure(tau_mag, reject)
        self.front = front  # the magnetometer's front end: calibration, latency (kept over a reset: the robot's)
        self.reset()

    def configure(self, tau_mag: float, reject: bool) -> None:
        """The run-time parameters: ``tau_mag`` (s), disturbance rejection on."""
        self.tau_mag = tau_mag
        self.reject = reject

    @property
    def delay(self) -> float:
        """The latency compensated now (s)."""
        return self.front.delay_s

    def reset(self) -> None:
        self.started = False  # the heading has been set from a field
        self.t = 0.0  # s since the first field
        self.n = 0  # fields used in the start phase
        self.norm_lp = self.dip_lp = 0.0
        self.ref_norm = self.ref_dip = 0.0
        self.cand_norm = self.cand_dip = 0.0
        self.cand_t = self.undist_t = self.reject_t = 0.0
        self.disturbed = False
        self.gyr_lp = 0.0
        self.gain = 0.0  # the last sample's gain toward the field (0: not corrected, 1: the field set the heading)
        self.reacq = False  # re-acquiring the heading after a hole (start phase without reference learning)
        self.weight = 0.0  # while re-acquiring: Σ of the weights (1/deg²) of the bridge and the fields since the hole
        self.gate = False  # the next field is tested against the bridge
        self.switch = False  # the configured calibration was rejected or restored since the last field
        self.wsum = 0.0  # Σ of the start's weights (relative to a calibrated field's: 1 each while trusted)
        self.cal_sd = 0.0  # the heading σ the calibration's estimate added to the last field (rad)
        self.doubt_sd = 0.0  # while the configured calibration is used: the σ of the doubt that it holds (rad)
        self.front.reset()

    @property
    def observed(self) -> bool:
        """The last sample's heading was corrected by the field."""
        return self.gain > 0.0

    def reacquire(self, bridge_sd: float | None = None) -> None:
        """A hole in the input: the rotation during it is not known well, so the heading re-converges to the
        field as at the start (for ``tau_mag`` s, the weighted mean of the module docstring; without a bridge,
        the first undisturbed field sets it), keeping the learned field reference and the latency estimate.
        ``bridge_sd``: standard deviation (deg) of the heading the gyro carried across the hole; None: no
        bridge (its weight is 0). A bridged hole while the field is rejected starts no re-acquisition: the first
        field to pass the norm and dip test again would set the heading at once, and a field that passes after
        being rejected is not a trusted one (an attached magnet's field passes in some orientations). The heading
        then carries on over the bridge, and takes the field at the usual gain once it is accepted."""
        self.front.restart()
        if self.started and not (self.disturbed and bridge_sd):
            self.t, self.reacq = 0.0, True
            self.weight = 1.0 / (bridge_sd * bridge_sd) if bridge_sd else 0.0
            self.gate = self.weight > 0.0

    def step(self, q: Quat, delta: Quat, dt: float, mag: Vec | None,
             tilt_sd: float = 0.0) -> float:
        """The heading correction (rad, about world z) for the output ``q`` of this sample before correction;
        ``delta`` is the sample's bias-corrected gyro increment (sensor frame), ``mag`` its field or None,
        ``tilt_sd`` the standard deviation (deg) of ``q``'s inclination after a hole (0: converged)."""
        self.gain = 0.0
        mag = self._through_front_end(q, delta, dt, mag)
        if mag is None:
            return 0.0
        mn = math.sqrt(mag[0] * mag[0] + mag[1] * mag[1] + mag[2] * mag[2])
        mw = rotate(q, mag)
        if mw[0] * mw[0] + mw[1] * mw[1] <= 0.0:
            return 0.0  # the field is vertical: no heading information
        err = heading_angle(mw[0], mw[1])
        dip = -math.asin(max(-1.0, min(1.0, mw[2] / mn)))
        scale = self._weight(q, mw)
        if not self.started or (self.switch and self._switched(mn, dip)):
            self._begin(mn, dip, scale)
            return err
        self.t += dt
        k = dt / self.tau_mag * scale
        start = self.t < self.tau_mag or scale < 0.5  # open while the calibration adds more than the field's σ
        self.reacq = self.reacq and start
        initial = start and not self.reacq  # the first start: the field reference is learned too
        if initial:
            self.n += 1
            self.wsum += scale
            k = max(k, scale / self.wsum)
        if self.reject:
            k = self._disturbance(mn, dip, dt, k, initial)
        if self.reacq and k > 0.0 and not self.disturbed:  # (not the half gain after a long rejection)
            k = max(k, self._reacquire_gain(err, mw, tilt_sd))
        self.gain = k
        return k * err

    def _through_front_end(self, q: Quat, delta: Quat, dt: float, mag: Vec | None) -> Vec | None:
        """The gyro's rate low-pass; the sample through the magnetometer's front end (every sample once a field came:
        the calibration's windows and the latency fit need its gyro), which gives the field calibrated and rotated
        back over the latency, or None. When the configured calibration is rejected or restored, the next field
        sets the heading anew (:meth:`_switched`)."""
        w = to_rotvec(delta)
        rate = math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]) / dt if dt > 0.0 else 0.0
        self.gyr_lp += dt / (GYR_LP_TAU + dt) * (rate - self.gyr_lp)
        out = self.front.step(delta, w, dt, mag, q, not self.disturbed)
        if out.switched:  # rejected, or (a changed magnetic situation) restored
            self.cal_sd, self.switch = 0.0, True
        return out.field_t

    def _weight(self, q: Quat, mw: Vec) -> float:
        """This field heading's weight relative to a calibrated one's, ``σ_m²/(σ_m² + σ_c²)`` (1 while the
        configured calibration holds, or without the online calibration; the σ its doubt leaves then goes to
        :attr:`doubt_sd`)."""
        front = self.front
        if not front.calibrating:
            return 1.0
        if front.trusted:  # used as configured; the doubt the windows leave goes to the σ only (stage 8)
            self.doubt_sd = front.heading_sd(q, mw)
            return 1.0
        self.doubt_sd = 0.0
        self.cal_sd = front.heading_sd(q, mw)
        return MAG_SD * MAG_SD / (MAG_SD * MAG_SD + self.cal_sd * self.cal_sd)

    def _switched(self, norm: float, dip: float) -> bool:
        """The configured calibration was just rejected, or restored; ``norm``, ``dip``: the first field calibrated
        anew. If the field was being rejected as disturbed and the newly calibrated one fits the field reference
        again, the magnetic situation changed under a heading the gyro held (a magnet attached, or taken off): that
        heading bridges to the new fields, its σ the field heading's at the last accepted field plus the residual
        gyro bias over the time rejected (returns False: carry on). Otherwise, after a rejection, the heading and the
        reference came from fields calibrated wrongly: this field sets both anew (returns True)."""
        self.switch = False  # (the bands as for a calibrated field: the new calibration is one, or nothing fits)
        fits = abs(norm - self.ref_norm) < NORM_TH * self.ref_norm and abs(dip - self.ref_dip) < DIP_TH
        if not (self.started and self.disturbed and fits):
            return not self.front.trusted
        bridge_deg = math.hypot(MAG_HEADING_SD_DEG, GYRO_BIAS_RESIDUAL_SD_RAD_S / DEG * self.reject_t)
        self.t, self.reacq, self.gate = 0.0, True, True
        self.weight = 1.0 / (bridge_deg * bridge_deg)
        return False

    def _begin(self, norm: float, dip: float, scale: float) -> None:
        """The first field (since a reset, or since the configured calibration was rejected) sets the heading and
        the field reference; ``scale`` its weight in the start's mean."""
        self.started = True
        self.t, self.n, self.wsum, self.reacq = 0.0, 1, scale, False
        self.norm_lp = self.ref_norm = self.cand_norm = norm
        self.dip_lp = self.ref_dip = self.cand_dip = dip
        self.gain = 1.0

    def _reacquire_gain(self, err: float, mw: Vec, tilt_sd: float) -> float:
        """The weight of this field's heading (error ``err``, rad; world-frame field ``mw``) in the mean since the
        hole; the first field after a hole also tests the bridge (module docstring)."""
        tan_dip = abs(mw[2]) / math.sqrt(mw[0] * mw[0] + mw[1] * mw[1])
        var = REACQUIRE_FIELD_SD_DEG * REACQUIRE_FIELD_SD_DEG + (tan_dip * tilt_sd) ** 2 + (self.cal_sd / DEG) ** 2
        if self.gate:  # the first field after the hole: is the bridge consistent with it?
            self.gate = False
            if (err / DEG) ** 2 > BRIDGE_GATE * BRIDGE_GATE * (1.0 / self.weight + var):
                self.weight = 0.0
        w = 1.0 / var
        self.weight += w
        return w / self.weight

    def _disturbance(self, n: float, dip: float, dt: float, k: float, start: bool) -> float:
        """VQF-style magnetic disturbance detection; the gain to use for this sample."""
        c = dt / (CURRENT_TAU + dt)
        self.norm_lp += c * (n - self.norm_lp)
        self.dip_lp += c * (dip - self.dip_lp)
        n, dip = self.norm_lp, self.dip_lp
        k_ref = dt / REF_TAU
        if start:  # the reference is the running mean of the start (assumed undisturbed)
            kr = max(k_ref, 1.0 / self.n)
            self.ref_norm += kr * (n - self.ref_norm)
            self.ref_dip += kr * (dip - self.ref_dip)
            self.cand_norm, self.cand_dip = self.ref_norm, self.ref_dip
            return k
        front = self.front
        band = 0.0 if not front.calibrating or front.trusted else CAL_BAND * front.field_sd_t()  # T
        if abs(n - self.ref_norm) < NORM_TH * self.ref_norm + band and abs(dip - self.ref_dip) < DIP_TH + band / n:
            self.undist_t += dt
            if self.undist_t >= MIN_UNDISTURBED:
                self.disturbed = False
                self.ref_norm += k_ref * (n - self.ref_norm)
                self.ref_dip += k_ref * (dip - self.ref_dip)
        else:
            self.undist_t = 0.0
            self.disturbed = True
        self._new_field(n, dip, dt, k_ref)
        if self.disturbed:
            if self.reject_t <= MAX_REJECT:
                self.reject_t += dt
                return 0.0
            return k / REJECT_FACTOR
        self.reject_t = max(self.reject_t - REJECT_FACTOR * dt, 0.0)
        return k

    def _new_field(self, n: float, dip: float, dt: float, k_ref: float) -> None:
        """A new stable field (norm and dip steady while moving for NEW_TIME) becomes the reference."""
        if abs(n - self.cand_norm) < NORM_TH * self.cand_norm and abs(dip - self.cand_dip) < DIP_TH:
            if self.gyr_lp >= NEW_MIN_GYR:
                self.cand_t += dt
            self.cand_norm += k_ref * (n - self.cand_norm)
            self.cand_dip += k_ref * (dip - self.cand_dip)
            if self.disturbed and self.cand_t >= NEW_TIME:
                self.ref_norm, self.ref_dip = self.cand_norm, self.cand_dip
                self.disturbed = False
                self.undist_t = MIN_UNDISTURBED
        else:
            self.cand_t = 0.0
            self.cand_norm, self.cand_dip = n, dip
