"""RIANN's absolute heading from the magnetometer (ROS-free): a heading-only correction with disturbance rejection.

RIANN estimates inclination only. Its output is ``q = Rz(ψ) ⊗ q_c``: ``q_c`` the (carried) network attitude,
which fixes roll and pitch, and ``ψ`` a heading angle about the world vertical. Without a field, ``ψ``
follows the bias-corrected gyro (:meth:`RiannEstimator._compose`). With a field, each sample also does

1. **latency compensation**: a field read ``D`` seconds behind the gyro is rotated into the sensor frame of
   the sample's stamp with the gyro increments of the last ``D`` seconds, ``m ← R(r)ᵀ m``. ``D`` is estimated
   online (:class:`LatencyEstimator`, starting from ``mag_delay``) or fixed at ``mag_delay``;
2. **tilt compensation**: ``m_w = R(q) m``; the heading error is ``e = atan2(m_w,x, m_w,y)`` (zero when the
   horizontal field points along +y: magnetic north in ENU) and the dip is ``−asin(m_w,z / |m|)``;
3. **disturbance test** (as VQF, Laidig & Seel 2023, with VQF's default constants): the low-passed norm and
   dip are compared with a reference learned online; a field off by more than 10 % in norm or 10° in dip is
   disturbed — the heading then follows the gyro only (for at most 60 s, after which the correction runs at
   half gain, so a permanently changed field is accepted again); a new field that stays stable for 20 s of
   motion becomes the reference;
4. **correction**: ``ψ ← ψ + k e`` with ``k = dt / tau_mag`` (during the first ``tau_mag`` seconds at least
   ``1/n``: the running mean of the magnetic heading, so the start converges at once). The first usable field
   sets the heading outright. After a hole in the input (:meth:`MagHeading.reacquire`) the heading re-converges
   the same way, since the rotation during the hole is only roughly known, but as an inverse-variance weighted
   mean (below).

**Re-acquiring after a hole.** Two things are uncertain after a hole: the heading the gyro carried across it
(the bridge, standard deviation ``σ_b`` from :func:`~riann_ros.estimators.holes.bridge_sigma`) and, for a
while, the inclination (the hand-over of :mod:`~riann_ros.estimators.holes`, standard deviation ``σ_t(t)``
falling as the fresh network converges). The tilt compensation turns an inclination error into a heading error
of up to ``tan(dip)`` times it (2.6× at a dip of 69°), so a field read in the first few tenths of a second
after a hole in fast motion can be off by tens of degrees. The heading is therefore the weighted mean of the
bridged heading (weight ``1/σ_b²``) and each field heading since the hole (weight
``1/(σ_m² + tan²(dip) σ_t²)``, ``σ_m`` = :data:`MAG_HEADING_SD`), carried by the gyro: the gain of a sample is
``w / Σw``, never below ``dt / tau_mag``. Without a bridge (a gap longer than ``max_dt``) and with a converged
inclination this is the plain running mean of the start. The bridge's ``σ_b`` comes from the rates at the hole's
ends, so a turn made entirely inside the hole (still before and after it) escapes it: if the first usable field
after the hole differs from the bridged heading by more than :data:`BRIDGE_GATE` combined standard deviations,
the bridge is dropped and the field sets the heading, as without one.

The correction is a rotation about the world vertical, so the sensor-frame vertical — RIANN's inclination —
is never changed by the magnetometer (tested: 9D inclination = 6D inclination). The vertical gyro bias is
left to the gyro-bias front end in front of the network.
"""

from __future__ import annotations

import math

DEG = math.pi / 180.0
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
# online latency fit (LatencyEstimator)
WINDOW = 0.1  # s; the field's rotation is compared with the gyro's over windows this long
MAX_WINDOW = 0.2  # s; a longer window (no field, a gap) is dropped
DELAY_TAU = 30.0  # s of windows; older windows are forgotten with this time constant
DELAY_PRIOR = 1.0  # (rad/s)²; the starting value weighs as much as one window with a 1 rad/s change of rate
MAX_DELAY = 0.1  # s; the largest latency compensated
# re-acquiring after a hole
MAG_HEADING_SD = 5.0  # deg; one field heading's error apart from the tilt (the default mag_yaw_stddev_deg)
BRIDGE_GATE = 3.0  # the bridge is dropped if the first field after the hole is this many standard deviations off

Quat = tuple[float, float, float, float]


def qmul(p: Quat, q: Quat) -> Quat:
    """Quaternion product p ⊗ q in plain floats (shared with :mod:`~riann_ros.estimators.riann`)."""
    pw, px, py, pz = p
    qw, qx, qy, qz = q
    return (pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw)


def _rotate(q: Quat, v: tuple[float, float, float]) -> tuple[float, float, float]:
    """R(q) v for a unit quaternion q."""
    w, x, y, z = q
    vx, vy, vz = v
    tx = 2.0 * (y * vz - z * vy)
    ty = 2.0 * (z * vx - x * vz)
    tz = 2.0 * (x * vy - y * vx)
    return (vx + w * tx + (y * tz - z * ty), vy + w * ty + (z * tx - x * tz), vz + w * tz + (x * ty - y * tx))


def _cross(a: tuple[float, float, float], b: tuple[float, float, float]) -> tuple[float, float, float]:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _rotvec(q: Quat) -> tuple[float, float, float]:
    """Rotation vector of a unit quaternion (small angles fine)."""
    w, x, y, z = q
    s = math.sqrt(x * x + y * y + z * z)
    if s < 1e-12:
        return (2.0 * x, 2.0 * y, 2.0 * z)
    a = 2.0 * math.atan2(s, w) / s
    return (a * x, a * y, a * z)


def from_rotvec(x: float, y: float, z: float) -> Quat:
    """Unit quaternion of a rotation vector, plain floats (shared with :mod:`~riann_ros.estimators.riann`)."""
    a = math.sqrt(x * x + y * y + z * z)
    if a < 1e-12:
        return (1.0, 0.5 * x, 0.5 * y, 0.5 * z)
    k = math.sin(0.5 * a) / a
    return (math.cos(0.5 * a), x * k, y * k, z * k)


class LatencyEstimator:
    """Online, reference-free estimate of the magnetometer's latency ``D`` behind the gyro.

    A constant world field seen by a rotating sensor obeys ``m(t₁) = R(ρ)ᵀ m(t₀)``, ``ρ`` the gyro's rotation
    from ``t₀`` to ``t₁``. A field read ``D`` late rotates as the gyro did ``D`` earlier; to first order the
    prediction error over a window is ``e = m₁ − R(ρ)ᵀ m₀ ≈ D g`` with ``g = ω₁ × R(ρ)ᵀ m₀ − R(ρ)ᵀ (ω₀ × m₀)``
    (``ω₀``, ``ω₁`` the rates at the window's ends). ``D`` is the least-squares fit of ``e`` on ``g`` over
    windows of :data:`WINDOW` s with exponential forgetting (:data:`DELAY_TAU`), both normalised by ``|m|²``
    and started from a prior (the ``mag_delay`` parameter, weight :data:`DELAY_PRIOR`). Windows carry
    information only while the rate changes, so at rest the estimate holds. Noise in the field enters ``e``
    and ``g`` in ways that cancel in ``e·g`` (``n · (ω × n) = 0``), so the fit is unbiased by it; a constant
    hard-iron residual adds a term uncorrelated with ``g`` on average. Windows with a disturbed field are not
    used (the model needs a constant world field).
    """

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self.m0: tuple[float, float, float] | None = None  # field at the window's start
        self.w0 = self.w = (0.0, 0.0, 0.0)  # rate at the window's start, newest rate (rad/s)
        self.rho: Quat = (1.0, 0.0, 0.0, 0.0)  # gyro rotation since the window's start
        self.t = 0.0  # s since the window's start
        self.num = self.den = 0.0  # Σ e·g, Σ g·g (normalised, forgotten)
        self.windows = 0

    def delay(self, start: float) -> float:
        """The latency to compensate (s): the fit with ``start`` as its prior, within [0, MAX_DELAY]."""
        d = (DELAY_PRIOR * start + self.num) / (DELAY_PRIOR + self.den)
        return min(max(d, 0.0), MAX_DELAY)

    def add(self, delta: Quat, rv: tuple[float, float, float], dt: float,
            mag: tuple[float, float, float] | None) -> None:
        """One sample: its gyro increment (quaternion and rotation vector) and its undisturbed field or None."""
        if dt > 0.0:
            self.w = (rv[0] / dt, rv[1] / dt, rv[2] / dt)
        if self.m0 is not None:
            self.rho = qmul(self.rho, delta)
            self.t += dt
            if self.t < WINDOW:
                return
            if mag is not None and self.t <= MAX_WINDOW:
                self._fit(mag)
        if mag is not None:
            self.m0, self.w0, self.rho, self.t = mag, self.w, (1.0, 0.0, 0.0, 0.0), 0.0
        else:
            self.m0 = None

    def _fit(self, m1: tuple[float, float, float]) -> None:
        m0 = self.m0
        assert m0 is not None
        rc = (self.rho[0], -self.rho[1], -self.rho[2], -self.rho[3])
        p = _rotate(rc, m0)
        w0, w1 = self.w0, self.w
        c0 = _rotate(rc, _cross(w0, m0))
        c1 = _cross(w1, p)
        g = (c1[0] - c0[0], c1[1] - c0[1], c1[2] - c0[2])
        n2 = m0[0] * m0[0] + m0[1] * m0[1] + m0[2] * m0[2]
        if n2 <= 0.0:
            return
        f = math.exp(-self.t / DELAY_TAU)
        self.num = f * self.num + ((m1[0] - p[0]) * g[0] + (m1[1] - p[1]) * g[1] + (m1[2] - p[2]) * g[2]) / n2
        self.den = f * self.den + (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]) / n2
        self.windows += 1


class MagHeading:
    """The heading correction state (see the module docstring); :meth:`step` per sample."""

    def __init__(self, tau_mag: float, mag_delay: float, reject: bool, estimate_delay: bool = True) -> None:
        self.tau_mag = tau_mag
        self.mag_delay = mag_delay  # fixed latency, or the estimate's starting value
        self.reject = reject
        self.estimate_delay = estimate_delay
        self.latency = LatencyEstimator()
        self.reset()

    @property
    def delay(self) -> float:
        """The latency compensated now (s)."""
        return self.latency.delay(self.mag_delay) if self.estimate_delay else self.mag_delay

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
        self.hist: list[tuple[float, float, float, float]] = []  # (dt, rotation vector of the increment)
        self.observed = False  # the last sample's heading was corrected by the field
        self.reacq = False  # re-acquiring the heading after a hole (start phase without reference learning)
        self.weight = 0.0  # while re-acquiring: Σ of the weights (1/deg²) of the bridge and the fields since the hole
        self.gate = False  # the next field is tested against the bridge
        self.latency.reset()

    def reacquire(self, bridge_sd: float | None = None) -> None:
        """A hole in the input: the rotation during it is not known well, so the heading re-converges to the
        field as at the start (for ``tau_mag`` s, the weighted mean of the module docstring; without a bridge,
        the first undisturbed field sets it), keeping the learned field reference and the latency estimate.
        ``bridge_sd``: standard deviation (deg) of the heading the gyro carried across the hole; None: no
        bridge (its weight is 0)."""
        if self.started:
            self.t, self.reacq = 0.0, True
            self.weight = 1.0 / (bridge_sd * bridge_sd) if bridge_sd else 0.0
            self.gate = self.weight > 0.0

    def _delay_rotation(self, delta: Quat, dt: float) -> Quat:
        """Sensor-frame rotation over the last :attr:`delay` s from the gyro increments (oldest partial)."""
        rx, ry, rz = _rotvec(delta)
        self.hist.append((dt, rx, ry, rz))
        r: Quat = (1.0, 0.0, 0.0, 0.0)
        rem = self.delay
        keep = 0
        for h_dt, hx, hy, hz in reversed(self.hist):
            if rem <= 0.0:
                break
            keep += 1
            f = min(h_dt, rem) / h_dt if h_dt > 0.0 else 0.0
            rem -= h_dt
            r = qmul(from_rotvec(hx * f, hy * f, hz * f), r)
        del self.hist[: len(self.hist) - max(keep, 1)]
        return r

    def step(self, q: Quat, delta: Quat, dt: float, mag: tuple[float, float, float] | None,
             tilt_sd: float = 0.0) -> float:
        """The heading correction (rad, about world z) for the output ``q`` of this sample before correction;
        ``delta`` is the sample's bias-corrected gyro increment (sensor frame), ``mag`` its field or None,
        ``tilt_sd`` the standard deviation (deg) of ``q``'s inclination after a hole (0: converged)."""
        self.observed = False
        w = _rotvec(delta)
        rate = math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]) / dt if dt > 0.0 else 0.0
        self.gyr_lp += dt / (GYR_LP_TAU + dt) * (rate - self.gyr_lp)
        if self.estimate_delay:
            self.latency.add(delta, w, dt, None if self.disturbed else mag)
        if self.estimate_delay or self.mag_delay > 0.0:
            r = self._delay_rotation(delta, dt)
            if mag is not None:
                mag = _rotate((r[0], -r[1], -r[2], -r[3]), mag)
        if mag is None:
            return 0.0
        mn = math.sqrt(mag[0] * mag[0] + mag[1] * mag[1] + mag[2] * mag[2])
        mw = _rotate(q, mag)
        if mw[0] * mw[0] + mw[1] * mw[1] <= 0.0:
            return 0.0  # the field is vertical: no heading information
        err = math.atan2(mw[0], mw[1])
        dip = -math.asin(max(-1.0, min(1.0, mw[2] / mn)))
        if not self.started:
            self.started = True
            self.t, self.n = 0.0, 1
            self.norm_lp = self.ref_norm = self.cand_norm = mn
            self.dip_lp = self.ref_dip = self.cand_dip = dip
            self.observed = True
            return err
        self.t += dt
        k = dt / self.tau_mag
        start = self.t < self.tau_mag
        self.reacq = self.reacq and start
        initial = start and not self.reacq  # the first start: the field reference is learned too
        if initial:
            self.n += 1
            k = max(k, 1.0 / self.n)
        if self.reject:
            k = self._disturbance(mn, dip, dt, k, initial)
        if self.reacq and k > 0.0 and not self.disturbed:  # (not the half gain after a long rejection)
            k = max(k, self._reacquire_gain(err, mw, tilt_sd))
        self.observed = k > 0.0
        return k * err

    def _reacquire_gain(self, err: float, mw: tuple[float, float, float], tilt_sd: float) -> float:
        """The weight of this field's heading (error ``err``, rad; world-frame field ``mw``) in the mean since the
        hole; the first field after a hole also tests the bridge (module docstring)."""
        tan_dip = abs(mw[2]) / math.sqrt(mw[0] * mw[0] + mw[1] * mw[1])
        var = MAG_HEADING_SD * MAG_HEADING_SD + (tan_dip * tilt_sd) ** 2
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
        if abs(n - self.ref_norm) < NORM_TH * self.ref_norm and abs(dip - self.ref_dip) < DIP_TH:
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
