"""Stage 7, the heading: RIANN's inclination with a heading that follows the gyro, and the field when there is one
(ROS-free).

RIANN estimates inclination (roll, pitch) only; its yaw is not meaningful. The output is ``Rz(ψ) ⊗ q_c``: ``q_c``
the carried (and handed-over) network attitude fixes roll and pitch, and the heading ``ψ`` starts at zero and
follows the bias-corrected gyro: each output is the gyro prediction from the previous one, corrected by the
smallest rotation about a horizontal axis that gives it the network's gravity direction (``ψ`` grows by the twist
of ``q_prev ⊗ δ ⊗ q_c⁻¹``). From the first sample with a field on, the magnetic heading (:mod:`.s7a_mag`)
adds a correction about the vertical, so the inclination is the same with and without a field. docs/riann.md,
stage 7, and docs/magnetometer.md.

Blocks of up to :data:`~.stage.SMALL_BLOCK` samples run sample by sample in plain floats (:meth:`Heading._one`),
longer ones vectorised up to the first field (:meth:`Heading._vector`, the reference); a test holds the two equal
on random blocks.
"""

from __future__ import annotations

import math

import numpy as np

from riann_ros import quaternion as quat
from riann_ros.estimators.base import Array
from riann_ros.estimators.riann.s7a_mag import MagHeading
from riann_ros.estimators.riann.stage import SMALL_BLOCK, Cause, HeadingBlock, HeadingIn, Quat, Vec
from riann_ros.magcal.frontend import MagFrontEnd
from riann_ros.rotations import about_z, conj, qmul, twist


class Heading:
    """Stage 7 (see the module docstring)."""

    NAME = "heading"

    def __init__(self, tau_mag_s: float, reject: bool, front: MagFrontEnd) -> None:
        self.mag = MagHeading(tau_mag_s, reject, front)
        self.restart(Cause.RESET)

    def use_front_end(self, front: MagFrontEnd) -> None:
        """The magnetometer's front end the heading takes its field from from now on (the stream's)."""
        self.mag.front = front

    def configure(self, tau_mag_s: float, reject: bool) -> None:
        """The run-time parameters of the magnetic heading (:meth:`.s7a_mag.MagHeading.configure`)."""
        self.mag.configure(tau_mag_s, reject)

    def restart(self, cause: Cause) -> None:
        """RESET: the heading anew (zero, or the first field); GAP: kept, the field re-acquired without a bridge (a
        hole: re-acquired in run(), where the hole is)."""
        if cause is Cause.RESET:
            self.psi = 0.0  # heading of the output (rad)
            self.q_prev: Quat | None = None  # the previous sample's carried network attitude
            self.mag.reset()
        else:
            self.mag.reacquire()

    def run(self, block: HeadingIn) -> HeadingBlock:
        """The output attitudes, and per sample the gain toward the field and the reference dip."""
        s, h = block.samples, block.handover
        qc, delta, dt, mag, bridges, tilt_sd = h.q, block.carry.delta, s.step_s, s.mag, h.bridge_sd_deg, h.blend_sd_deg
        gain = [0.0] * len(qc)
        dip = [0.0] * len(qc)
        cal = [0.0] * len(qc)
        doubt = [0.0] * len(qc)
        self._cal_sd, self._doubt_sd = cal, doubt  # filled where the magnetic heading runs
        if len(qc) <= SMALL_BLOCK:
            q = np.array([self._one(i, qc[i], delta[i], dt[i], None if mag is None else mag[i], bridges.get(i),
                                    tilt_sd[i], gain, dip) for i in range(len(qc))])
        else:
            q = self._vector(block, gain, dip)
        return HeadingBlock(q, gain, dip, cal, doubt)

    def _one(self, i: int, qc: Quat, delta: Quat, dt: float, mag: Vec | None, bridge: float | None, tilt_sd: float,
             gain: list[float], dip: list[float]) -> Quat:
        """:meth:`_vector` of sample ``i`` in plain floats (its gain and dip into ``gain[i]``, ``dip[i]``)."""
        if bridge is not None:
            self.mag.reacquire(bridge)
        if self.q_prev is None:
            self.psi = -2.0 * math.atan2(qc[3], qc[0])  # the output starts at zero heading
        else:
            self.psi = math.remainder(self.psi + twist(qmul(qmul(self.q_prev, delta), conj(qc))), math.tau)
        self.q_prev = qc
        if mag is not None or self.mag.started:
            qo = qmul(about_z(self.psi), qc)
            self.psi = math.remainder(self.psi + self.mag.step(qo, delta, dt, mag, tilt_sd), math.tau)
            gain[i] = self.mag.gain
            dip[i] = self.mag.ref_dip
            self._cal_sd[i], self._doubt_sd[i] = self.mag.s.cal_sd, self.mag.doubt_sd()
        w, x, y, z = qmul(about_z(self.psi), qc)
        n = math.sqrt(w * w + x * x + y * y + z * z)
        if w < 0.0:  # sign convention: w >= 0
            n = -n
        return (w / n, x / n, y / n, z / n)

    def _vector(self, block: HeadingIn, gain: list[float], dip: list[float]) -> Array:
        """The reference, vectorised over the block up to its first field (then sample by sample)."""
        s, h = block.samples, block.handover
        qc_l, delta, dt, mag = h.q, block.carry.delta, s.step_s, s.mag
        bridges, tilt_sd = h.bridge_sd_deg, h.blend_sd_deg
        qc = np.asarray(qc_l)
        n = len(qc)
        prev = np.vstack([np.asarray(self.q_prev or qc_l[0])[None, :], qc[:-1]])
        e = quat.multiply(quat.multiply(prev, np.asarray(delta)), quat.conjugate(qc))
        tw = np.remainder(2.0 * np.arctan2(e[:, 3], e[:, 0]) + np.pi, math.tau) - np.pi
        if self.q_prev is None:
            tw[0] = -2.0 * math.atan2(qc[0, 3], qc[0, 0]) - self.psi  # the output starts at zero heading
        first = self._first_field(mag, n)
        psi = self.psi + np.cumsum(tw)
        if first < n:
            psi[first:] = self._mag_psi(float(psi[first - 1]) if first else self.psi, tw[first:], qc_l[first:],
                                        delta[first:], dt[first:], None if mag is None else mag[first:],
                                        {k - first: b for k, b in bridges.items() if k >= first}, tilt_sd[first:],
                                        gain, dip, first)
        self.psi = math.remainder(float(psi[-1]), math.tau)
        self.q_prev = qc_l[-1]
        rz = np.column_stack([np.cos(0.5 * psi), np.zeros(n), np.zeros(n), np.sin(0.5 * psi)])
        q = quat.normalize(quat.multiply(rz, qc))
        return np.where(q[:, :1] < 0.0, -q, q)  # sign convention: w >= 0

    def _first_field(self, mag: list[Vec | None] | None, n: int) -> int:
        """The first sample that runs the magnetic heading: 0 once a field was seen, else the first with a field."""
        if self.mag.started:
            return 0
        if mag is None:
            return n
        return next((i for i, m in enumerate(mag) if m is not None), n)

    def _mag_psi(self, psi: float, tw: Array, qc: list[Quat], delta: list[Quat], dt: list[float],
                 mag: list[Vec | None] | None, bridges: dict[int, float], tilt_sd: list[float], gain: list[float],
                 dip: list[float], first: int) -> Array:
        """Heading angles from the first field on (sample ``first`` of the block): the gyro increment, then the
        magnetic correction (each sample's gain and dip into ``gain``, ``dip`` from ``first`` on)."""
        out = np.empty(len(tw))
        step = self.mag.step
        for i, t in enumerate(tw.tolist()):
            if i in bridges:
                self.mag.reacquire(bridges[i])
            psi += t
            c, s = math.cos(0.5 * psi), math.sin(0.5 * psi)
            q = qc[i]
            qo = (c * q[0] - s * q[3], c * q[1] - s * q[2], c * q[2] + s * q[1], c * q[3] + s * q[0])
            psi += step(qo, delta[i], dt[i], None if mag is None else mag[i], tilt_sd[i])
            gain[first + i] = self.mag.gain
            dip[first + i] = self.mag.ref_dip
            self._cal_sd[first + i], self._doubt_sd[first + i] = self.mag.s.cal_sd, self.mag.doubt_sd()
            out[i] = psi
        return out

    def diagnostics(self) -> dict[str, str]:
        h = self.mag
        if not h.started:
            return {}
        late = h.front.late_s
        kind = "estimated" if h.front.latency_settings.estimate else "fixed"
        latency = f"{1e3 * late:.0f} (scanned: late)" if late is not None else f"{1e3 * h.delay:.1f} ({kind})"
        return {"magnetic disturbance": "detected" if h.disturbed else "none", "magnetometer latency (ms)": latency}
