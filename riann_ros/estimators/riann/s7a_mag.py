"""Stage 7a, the magnetic heading: a heading-only correction toward the field, with disturbance rejection (ROS-free).

Per sample with a field (:meth:`MagHeading.step`): the field comes through the magnetometer's front end
(:class:`~riann_ros.magcal.frontend.MagFrontEnd`, the stream's: calibrated, and rotated back by the gyro over the
magnetometer's latency, which the front end estimates), is tilt-compensated with the output attitude
(``m_w = R(q) m``; heading error :func:`~riann_ros.magcal.heading.heading_angle` of ``m_w``, zero when the
horizontal field points along +y, magnetic north in ENU), tested for disturbance against a reference norm and dip
learned online (stage 7c, :mod:`.s7c_disturbance`: VQF's rules and constants; then the heading follows the gyro
only), and the heading moves toward it with the gain ``dt / tau_mag`` (the running mean during the first
``tau_mag`` seconds). After a hole (:meth:`MagHeading.reacquire`; not while the field is rejected) it re-converges
as the inverse-variance weighted mean of the bridged heading and each field heading since, a field weighing less
while the inclination is uncertain (``1 / (σ_w² + tan²(dip) σ_t²)``, ``σ_w`` = :data:`REACQUIRE_FIELD_SD_DEG`, a
weight of its own: stage 8 reports the fitted field σ, :data:`~riann_ros.defaults.MAG_HEADING_SD_DEG`). The
correction is a rotation about the world vertical: the inclination is never changed by the field.

With the online calibration on (the front end's ``calibrating``; RIANN hands it its attitude as the tilt and whether
its disturbance test passed the last field) all of the above sees the calibrated field. While the configured
calibration is used (it holds the gyro-aided test, :mod:`riann_ros.magcal.hypothesis`, as the more probable
hypothesis) nothing else changes. Once the estimate is used
instead the heading starts over from the next field (the one it has was set by a field calibrated otherwise), and
each field heading counts as much as the calibration knows it: its weight is ``1/(σ_m² + σ_c²)`` (``σ_c`` the
heading σ the calibration adds at this sample, ``σ_m`` the field heading's own, stage 8's MAG_SD): the gain is
``dt/tau_mag · σ_m²/(σ_m² + σ_c²)``, and the start's inverse-variance mean stays open while ``σ_c > σ_m``; the
disturbance test widens its norm and dip bands by three of the calibrated field's σ. While the configured
calibration is used its gains are the usual ones: no other source of heading exists that the field could be weighed
against (the gyro's heading came from the same field); the doubt the windows leave about it goes to stage 8's σ
(:attr:`HeadingState.doubt_sd`). The state is one record, :class:`HeadingState`. docs/magnetometer.md has the
physics.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field

from riann_ros.constants import DEG
from riann_ros.defaults import MAG_HEADING_SD_DEG
from riann_ros.estimators.riann.s7c_disturbance import ReferenceState, disturbance
from riann_ros.magcal.changes import field_disagrees
from riann_ros.magcal.frontend import MagFrontEnd
from riann_ros.magcal.heading import heading_angle
from riann_ros.magcal.records import GYRO_BIAS_RESIDUAL_SD_RAD_S
from riann_ros.rotations import Quat, Vec, rotate, to_rotvec

GYR_LP_TAU = 0.5  # s, low-pass of |ω| for the disturbance test's new field (s7c_disturbance.NEW_MIN_GYR)
# re-acquiring after a hole
#: deg; the σ a field heading is weighed with against the bridged heading (and the fields before it) while the
#: heading re-acquires after a hole: a weight that sets how fast the heading leaves the bridge for the fields. It is
#: not the field heading's σ that stage 8 reports (MAG_HEADING_SD_DEG, fitted on BROAD); that one would weigh the
#: first fields after a hole four times as much
REACQUIRE_FIELD_SD_DEG = 5.0
BRIDGE_GATE = 3.0  # the bridge is dropped if the first field after the hole is this many standard deviations off
MAG_SD = MAG_HEADING_SD_DEG * DEG  # rad; a calibrated field heading's σ (stage 8's): a calibration's σ weighs on it
CAL_BAND = 3.0  # the disturbance bands widen by this many of the calibrated field's σ while it converges


@dataclass
class HeadingState:
    """Everything the magnetic heading changes (:attr:`MagHeading.s`; a reset is ``HeadingState()``)."""

    started: bool = False  # the heading has been set from a field
    t: float = 0.0  # s since the first field
    n: int = 0  # fields used in the start phase
    gyr_lp: float = 0.0  # rad/s; the low-passed rate
    gain: float = 0.0  # the last sample's gain toward the field (0: not corrected, 1: the field set the heading)
    reacq: bool = False  # re-acquiring the heading after a hole (start phase without reference learning)
    weight: float = 0.0  # while re-acquiring: Σ of the weights (1/deg²) of the bridge and the fields since the hole
    gate: bool = False  # the next field is tested against the bridge
    switch: bool = False  # the configured calibration was rejected or restored since the last field
    wsum: float = 0.0  # Σ of the start's weights (relative to a calibrated field's: 1 each while trusted)
    cal_sd: float = 0.0  # the heading σ the calibration's estimate added to the last field (rad)
    doubt_sd: float = 0.0  # while the configured calibration is used: the σ of the doubt that it holds (rad)
    ref: ReferenceState = field(default_factory=ReferenceState)  # the disturbance test's (stage 7c)


class MagHeading:
    """The heading correction (see the module docstring); :meth:`step` per sample. Its state is one record,
    :attr:`s` (:class:`HeadingState`); the magnetometer's front end it takes its field from is the robot's and
    outlives a reset."""

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
        self.s = HeadingState()
        self.front.reset()

    def snapshot(self) -> HeadingState:
        """The heading's state (the front end's is its own: :meth:`~riann_ros.magcal.frontend.MagFrontEnd.snapshot`)."""
        return copy.deepcopy(self.s)

    def restore(self, state: HeadingState) -> None:
        self.s = copy.deepcopy(state)

    # what the heading stage reads of the last sample
    @property
    def started(self) -> bool:
        return self.s.started

    @property
    def gain(self) -> float:
        return self.s.gain

    @property
    def ref_dip(self) -> float:
        return self.s.ref.ref_dip

    @property
    def disturbed(self) -> bool:
        return self.s.ref.disturbed

    @property
    def observed(self) -> bool:
        """The last sample's heading was corrected by the field."""
        return self.s.gain > 0.0

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
        s = self.s
        if s.started and not (s.ref.disturbed and bridge_sd):
            s.t, s.reacq = 0.0, True
            s.weight = 1.0 / (bridge_sd * bridge_sd) if bridge_sd else 0.0
            s.gate = s.weight > 0.0

    def step(self, q: Quat, delta: Quat, dt: float, mag: Vec | None,
             tilt_sd: float = 0.0) -> float:
        """The heading correction (rad, about world z) for the output ``q`` of this sample before correction;
        ``delta`` is the sample's bias-corrected gyro increment (sensor frame), ``mag`` its field or None,
        ``tilt_sd`` the standard deviation (deg) of ``q``'s inclination after a hole (0: converged)."""
        s = self.s
        s.gain = 0.0
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
        if not s.started or (s.switch and self._switched(mn, dip, q, mag)):
            self._begin(mn, dip, scale)
            return err
        s.t += dt
        k = dt / self.tau_mag * scale
        start = s.t < self.tau_mag or scale < 0.5  # open while the calibration adds more than the field's σ
        s.reacq = s.reacq and start
        initial = start and not s.reacq  # the first start: the field reference is learned too
        if initial:
            s.n += 1
            s.wsum += scale
            k = max(k, scale / s.wsum)
        if self.reject:
            front = self.front
            # T; (not asked during the start, which learns the reference without testing it)
            band = 0.0 if initial or not front.calibrating or front.trusted else CAL_BAND * front.field_sd_t()
            k = disturbance(s.ref, mn, dip, dt, k, s.n if initial else 0, band, s.gyr_lp)
        if s.reacq and k > 0.0 and not s.ref.disturbed:  # (not the half gain after a long rejection)
            k = max(k, self._reacquire_gain(err, mw, tilt_sd))
        s.gain = k
        return k * err

    def _through_front_end(self, q: Quat, delta: Quat, dt: float, mag: Vec | None) -> Vec | None:
        """The gyro's rate low-pass; the sample through the magnetometer's front end (every sample once a field came:
        the calibration's windows and the latency fit need its gyro), which gives the field calibrated and rotated
        back over the latency, or None. When the configured calibration is rejected or restored, the next field
        sets the heading anew (:meth:`_switched`)."""
        s = self.s
        w = to_rotvec(delta)
        rate = math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]) / dt if dt > 0.0 else 0.0
        s.gyr_lp += dt / (GYR_LP_TAU + dt) * (rate - s.gyr_lp)
        out = self.front.step(delta, w, dt, mag, q, not s.ref.disturbed)
        if out.switched:  # rejected, or (a changed magnetic situation) restored
            s.cal_sd, s.switch = 0.0, True
        return out.field_t

    def doubt_sd(self) -> float:
        """rad; the heading's doubt stage 8 reports beside the calibration's: the configured calibration's while it
        is used (:attr:`HeadingState.doubt_sd`) and the field's timing while the lag scan had not resolved it
        (:attr:`~riann_ros.magcal.frontend.MagFrontEnd.timing_sd`); the heading weighs the field without them."""
        return math.hypot(self.s.doubt_sd, self.front.timing_sd)

    def _weight(self, q: Quat, mw: Vec) -> float:
        """This field heading's weight relative to a calibrated one's, ``σ_m²/(σ_m² + σ_c²)`` (1 while the
        configured calibration holds, or without the online calibration; the σ its doubt leaves then goes to
        :attr:`HeadingState.doubt_sd`)."""
        front, s = self.front, self.s
        if not front.calibrating:
            return 1.0
        if front.trusted:  # used as configured; the doubt the windows leave goes to the σ only (stage 8)
            s.doubt_sd = front.heading_sd(q, mw)
            return 1.0
        s.doubt_sd = 0.0
        s.cal_sd = front.heading_sd(q, mw)
        return MAG_SD * MAG_SD / (MAG_SD * MAG_SD + s.cal_sd * s.cal_sd)

    def _switched(self, norm: float, dip: float, q: Quat, mag: Vec) -> bool:
        """The configured calibration was just rejected, or restored; ``norm``, ``dip``: the first field calibrated
        anew (``mag``, sensor frame, at the attitude ``q``). If the field was being rejected as disturbed and the
        newly calibrated one fits the field reference again, the magnetic situation changed under a heading the gyro
        held (a magnet attached, or taken off): that heading bridges to the new fields, its σ the field heading's at
        the last accepted field plus the residual gyro bias over the time rejected (returns False: carry on).
        Otherwise, after a rejection, the heading and the reference came from fields calibrated wrongly: this field
        sets both anew (returns True); after a restore, from fields the discarded estimate calibrated: this field
        sets both anew where the heading disagrees with it by more than the classical filters' realign rule allows
        (:func:`~riann_ros.magcal.changes.field_disagrees`, the restored calibration's doubt and the field heading's
        σ), else the heading carries on (an estimate close to the configured values taught it nothing wrong)."""
        s = self.s
        s.switch = False  # (the bands as for a calibrated field: the new calibration is one, or nothing fits)
        if not (s.started and s.ref.disturbed and s.ref.fits(norm, dip)):
            return not self.front.trusted or field_disagrees(q, mag, s.doubt_sd)
        bridge_deg = math.hypot(MAG_HEADING_SD_DEG, GYRO_BIAS_RESIDUAL_SD_RAD_S / DEG * s.ref.reject_t)
        s.t, s.reacq, s.gate = 0.0, True, True
        s.weight = 1.0 / (bridge_deg * bridge_deg)
        return False

    def _begin(self, norm: float, dip: float, scale: float) -> None:
        """The first field (since a reset, or since the configured calibration was rejected) sets the heading and
        the field reference; ``scale`` its weight in the start's mean."""
        s = self.s
        s.started = True
        s.t, s.n, s.wsum, s.reacq = 0.0, 1, scale, False
        s.ref.begin(norm, dip)
        s.gain = 1.0

    def _reacquire_gain(self, err: float, mw: Vec, tilt_sd: float) -> float:
        """The weight of this field's heading (error ``err``, rad; world-frame field ``mw``) in the mean since the
        hole; the first field after a hole also tests the bridge (module docstring)."""
        s = self.s
        tan_dip = abs(mw[2]) / math.sqrt(mw[0] * mw[0] + mw[1] * mw[1])
        var = REACQUIRE_FIELD_SD_DEG * REACQUIRE_FIELD_SD_DEG + (tan_dip * tilt_sd) ** 2 + (s.cal_sd / DEG) ** 2
        if s.gate:  # the first field after the hole: is the bridge consistent with it?
            s.gate = False
            if (err / DEG) ** 2 > BRIDGE_GATE * BRIDGE_GATE * (1.0 / s.weight + var):
                s.weight = 0.0
        w = 1.0 / var
        s.weight += w
        return w / s.weight
