"""The gyro's unit, tested online against the accelerometer: how far the gyro turns the gravity direction against how
far the accelerometer sees it turn (ROS-free).

The physics is the converter's (:mod:`riann_ros.datasets.gyro_tilt`, with its thresholds): a world-fixed direction
seen in the sensor frame turns with the sensor, ``du/dt = u × ω`` for the gravity direction ``u``, so between two
quasi-static instants the accelerometer's change of ``u`` and the gyro's integral of ``u × ω`` are the same vector;
a gyro in the wrong unit makes the integral k times as long (57.3 for deg/s read as rad/s, 1/9.81 for a value
divided by g). Here it runs causally, one sample at a time: from a quasi-static anchor (the low-passed ``|acc|``
within :data:`~riann_ros.datasets.gyro_tilt.STATIC_TOL` of its median over the first samples after the stream's
(re)start) the gyro's integral
is kept until a quasi-static sample where the gravity direction has turned at least
:data:`~riann_ros.datasets.gyro_tilt.TILT_MIN_DEG` and twice what the largest plausible bias turns it; if the gyro's
change points the accelerometer's way, the tilt's ratio ``|∫ u × ω dt| / |Δu|`` is kept; the next tilt starts
there. Both ends of a tilt must also be steady (the accelerometer's direction turned less than :data:`STEADY_DEG` over
:data:`STEADY_S`): a sensor held still between two motions accelerates little, where a linear acceleration within
the static band can fake a tilt of 15°. The verdict is a vote of the last :data:`KEEP` tilts: when at least
:data:`SLIP_MAJORITY` of them (and :data:`~riann_ros.datasets.units.TILT_MIN_COUNT`) have a ratio within
:data:`SLIP_BAND` of one of the unit slips (:data:`SLIPS`), the gyro is in that unit: an ERROR, and the estimate is
not to be trusted (every σ half a turn) for as long as the tilts say so. Steady ends are rare in continuous motion, so
tilts between quasi-static ends that are not steady vote too, for the large slips only (:data:`LOOSE_SLIP_MIN`: a
rate in deg/s, mrad/s or mdeg/s read as rad/s), which no linear acceleration imitates.

Rotation about the vertical alone does not move the gravity direction: a ground robot that only turns is not tested
(the verdict stays OK).
"""

from __future__ import annotations

import math
import statistics
from collections import deque

from riann_ros.constants import DEG, GRAVITY
from riann_ros.datasets.gyro_tilt import BIAS_MAX_DEG_S, COS_MIN, LOWPASS_S, STATIC_TOL, TILT_MIN_DEG, WINDOWS_S
from riann_ros.datasets.units import GYR_SCALES, TILT_MIN_COUNT
from riann_ros.gate import G_CHECK_SAMPLES
from riann_ros.monitors.base import Level, Verdict

#: s; the test takes the means of blocks this long (100 Hz: the motion it looks at lies below 10 Hz)
BLOCK_S = 0.01
#: the last this many tilts' ratios make the verdict (a unit fixed at run time clears it within as many tilts)
KEEP = 9
#: the unit slips tested, by the factor they scale the gyro's turn: a value in deg/s, mrad/s or mdeg/s read as rad/s,
#: rad/s read as deg/s, and a rate multiplied or divided by g (9.81) on the way
SLIPS: dict[str, float] = {
    **{f"{u} read as rad/s": 1.0 / f for u, f in GYR_SCALES.items() if f != 1.0},
    "rad/s read as deg/s": DEG,
    "multiplied by 9.81": GRAVITY,
    "divided by 9.81": 1.0 / GRAVITY,
}
#: a tilt votes for a slip when its ratio is within this factor of the slip's (the ratios of a right gyro on BROAD's
#: rotation trials lie within 0.72–1.19 of 1, 5th to 95th percentile); the slips are 9.81 or more apart
SLIP_BAND = 1.5
_LOG_BAND = math.log(SLIP_BAND)
#: the share of the last tilts that must vote for one slip (and at least TILT_MIN_COUNT): a moving robot's tilts made
#: by linear acceleration scatter, a wrong unit scales them all alike
SLIP_MAJORITY = 0.6
#: tilts whose ends are quasi-static but not steady vote only for slips of at least this factor: linear acceleration
#: within the static band fakes tilts whose ratios reach a few (95th percentile 6.5 on BROAD's trials), never 13
LOOSE_SLIP_MIN = 20.0
LOOSE_SLIPS = {k: v for k, v in SLIPS.items() if v >= LOOSE_SLIP_MIN}
#: the band of those votes: wider (their ratios scatter with the linear acceleration at their ends), still far above
#: what linear acceleration fakes (a factor 2 below 20 is 10)
LOOSE_BAND = 2.0
RIGHT = {"rad/s": 1.0}
#: s; a tilt longer than the converter's longest window starts anew (the bias's drift)
MAX_TILT_S = WINDOWS_S[-1]
#: s, deg; a tilt's ends are steady: the accelerometer's mean direction turned less than STEADY_DEG over STEADY_S
#: (a sensor that is not turning: a linear acceleration that keeps |acc| within STATIC_TOL still tilts the reading by
#: up to 17°, but a sensor held still between two motions accelerates little)
STEADY_S = 0.1
STEADY_DEG = 2.0
_COS_STEADY = math.cos(math.radians(STEADY_DEG))
_TILT_MIN = math.radians(TILT_MIN_DEG)
_BIAS_MAX = math.radians(BIAS_MAX_DEG_S)


class _Tilts:
    """One kind of tilt (module docstring): its open tilt since the anchor and the ratios of the last :data:`KEEP`."""

    def __init__(self) -> None:
        self.ratios: deque[float] = deque(maxlen=KEEP)
        self.count = 0  # tilts measured in all
        self.restart()

    def restart(self) -> None:
        self.u0: tuple[float, float, float] | None = None  # the open tilt's anchor
        self.turn = (0.0, 0.0, 0.0)  # ∫ u × ω dt since the anchor
        self.t = 0.0

    def advance(self, u: tuple[float, float, float], gx: float, gy: float, gz: float, dt: float, end: bool) -> bool:
        """The gravity direction ``u`` and the gyro over ``dt`` at the window's centre; ``end``: it may end a tilt (and
        anchor the next). Returns whether a tilt's ratio was added."""
        if self.u0 is None:
            if end:
                self.u0, self.turn, self.t = u, (0.0, 0.0, 0.0), 0.0
            return False
        ux, uy, uz = u
        bx, by, bz = self.turn
        self.turn = (bx + (uy * gz - uz * gy) * dt, by + (uz * gx - ux * gz) * dt, bz + (ux * gy - uy * gx) * dt)
        self.t += dt
        if self.t > MAX_TILT_S:
            self.u0 = u if end else None
            self.turn, self.t = (0.0, 0.0, 0.0), 0.0
            return False
        return end and self._close(u)

    def _close(self, u: tuple[float, float, float]) -> bool:
        """The tilt since the anchor is taken if it turned far enough and the gyro points the accelerometer's way."""
        assert self.u0 is not None
        (x0, y0, z0), (ux, uy, uz) = self.u0, u
        c = max(-1.0, min(1.0, x0 * ux + y0 * uy + z0 * uz))
        if math.acos(c) < max(_TILT_MIN, 2.0 * _BIAS_MAX * self.t):
            return False
        a = (ux - x0, uy - y0, uz - z0)
        b = self.turn
        na = math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
        nb = math.sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2])
        added = na > 0.0 and a[0] * b[0] + a[1] * b[1] + a[2] * b[2] >= COS_MIN * na * nb
        if added:
            self.ratios.append(nb / na)
            self.count += 1
        self.u0, self.turn, self.t = u, (0.0, 0.0, 0.0), 0.0
        return added

    def vote(self, slips: dict[str, float], band: float) -> tuple[str, float] | None:
        """The slip of ``slips`` that the last tilts agree on (:data:`SLIP_MAJORITY` of them, at least
        :data:`~riann_ros.datasets.units.TILT_MIN_COUNT`, within the factor ``band`` of it), or None."""
        n = len(self.ratios)
        if n < TILT_MIN_COUNT:
            return None
        need = max(TILT_MIN_COUNT, SLIP_MAJORITY * n)
        logs = [math.log(r) for r in self.ratios]
        lb = math.log(band)
        for name, factor in slips.items():
            lf = math.log(factor)
            if sum(1 for x in logs if abs(x - lf) < lb) >= need:
                return name, factor
        return None


class GyroUnitsMonitor:
    """The gyro's unit against the accelerometer's tilt rate (module docstring); :meth:`step` per accepted sample.
    It runs :data:`~riann_ros.datasets.gyro_tilt.LOWPASS_S` / 2 behind the stream: the accelerometer's direction is
    the converter's centred mean over ``LOWPASS_S``, which needs the samples after it (no lag against the gyro)."""

    NAME = "gyro units"

    def __init__(self) -> None:
        self.steady = _Tilts()  # between quasi-static, steady ends: every slip
        self.loose = _Tilts()  # between quasi-static ends: the large slips only (LOOSE_SLIP_MIN)
        self._verdict = Verdict(self.NAME)
        self.restart()

    @property
    def tilts(self) -> int:
        """Tilts measured in all (of both kinds)."""
        return self.steady.count + self.loose.count

    def restart(self) -> None:
        """A (re)start of the stream: the mean, the open tilts and the ``|acc|`` at rest anew (the median of the
        first :data:`~riann_ros.gate.G_CHECK_SAMPLES` samples, in the accelerometer's own unit, as the gate's
        g-units check takes it). The ratios are kept (the same sensor)."""
        self.acc_rest: float | None = None
        self._norms: list[float] = []
        self._block = [0.0] * 8  # Σ acc·dt, Σ gyr·dt, Σ dt, count of the open block
        self._win: deque[tuple[float, float, float, float, float, float, float]] = deque()  # acc, gyr, dt
        self._span = 0.0  # s covered by the window's steps
        self._sum = [0.0, 0.0, 0.0]  # Σ acc over the window
        self._dirs: deque[tuple[float, float, float, float]] = deque()  # the mean directions of STEADY_S, with dt
        self._hist_s = 0.0
        self.steady.restart()
        self.loose.restart()

    def step(self, ax: float, ay: float, az: float, gx: float, gy: float, gz: float, dt: float) -> None:
        """One accepted sample (acc in any unit, gyr as read, dt s): into the block of :data:`BLOCK_S`, whose means
        the test takes (the motion it looks at is below 10 Hz; a 1 kHz stream costs it a tenth of its samples)."""
        b = self._block
        b[0] += ax * dt
        b[1] += ay * dt
        b[2] += az * dt
        b[3] += gx * dt
        b[4] += gy * dt
        b[5] += gz * dt
        b[6] += dt
        b[7] += 1.0
        if b[6] < BLOCK_S:
            return
        h = b[6]
        if h > 0.0:
            self._sample(b[0] / h, b[1] / h, b[2] / h, b[3] / h, b[4] / h, b[5] / h, h)
        else:  # (steps of 0: a block of first samples after restarts)
            self._sample(ax, ay, az, gx, gy, gz, 0.0)
        self._block = [0.0] * 8

    def _sample(self, ax: float, ay: float, az: float, gx: float, gy: float, gz: float, dt: float) -> None:
        """One block's means (acc, gyr) over its ``dt`` s."""
        if self.acc_rest is None:
            self._norms.append(math.sqrt(ax * ax + ay * ay + az * az))
            if len(self._norms) == G_CHECK_SAMPLES:  # (of blocks: their means' norms)
                self.acc_rest = statistics.median(self._norms)
        win, sm = self._win, self._sum
        win.append((ax, ay, az, gx, gy, gz, dt))
        sm[0] += ax
        sm[1] += ay
        sm[2] += az
        self._span += dt
        if self._span < LOWPASS_S:
            return
        while len(win) > 1 and self._span - win[1][6] >= LOWPASS_S:  # the window: LOWPASS_S of steps
            old = win.popleft()
            sm[0] -= old[0]
            sm[1] -= old[1]
            sm[2] -= old[2]
            self._span -= win[0][6]
        c = win[len(win) // 2]  # the sample at the window's centre: its gyro, its step, the mean direction
        n = len(win)
        self._centre(sm[0] / n, sm[1] / n, sm[2] / n, c[3], c[4], c[5], c[6])

    def _centre(self, lx: float, ly: float, lz: float, gx: float, gy: float, gz: float, dt: float) -> None:
        """The tilt tests at the window's centre: ``(lx, ly, lz)`` the mean accelerometer, the centre's gyro, step."""
        n = math.sqrt(lx * lx + ly * ly + lz * lz)
        if not (0.0 < n < math.inf and self.acc_rest):
            return
        u = (lx / n, ly / n, lz / n)
        hist = self._dirs
        hist.append((*u, dt))
        self._hist_s += dt
        while len(hist) > 1 and self._hist_s - hist[0][3] >= STEADY_S:
            self._hist_s -= hist.popleft()[3]
        px, py, pz, _ = hist[0]  # the direction STEADY_S ago
        static = abs(n / self.acc_rest - 1.0) < STATIC_TOL
        steady = static and self._hist_s >= 0.5 * STEADY_S and px * u[0] + py * u[1] + pz * u[2] >= _COS_STEADY
        new = self.steady.advance(u, gx, gy, gz, dt, steady)
        new = self.loose.advance(u, gx, gy, gz, dt, static) or new
        if new:
            self._verdict = self._judge()

    def slip(self) -> tuple[str, float] | None:
        """The unit slip the last tilts agree on (:data:`SLIPS`: its name and factor), or None (module docstring)."""
        return self.steady.vote(SLIPS, SLIP_BAND) or self.loose.vote(LOOSE_SLIPS, LOOSE_BAND)

    def right_unit(self) -> bool:
        """The last tilts (steady, or else any) agree with rad/s: what clears a slip found before."""
        return bool(self.steady.vote(RIGHT, SLIP_BAND) or self.loose.vote(RIGHT, SLIP_BAND))

    @property
    def ratio(self) -> float | None:
        """The median ratio gyro / accelerometer of the last steady tilts, else of the last tilts (None: too few)."""
        for t in (self.steady, self.loose):
            if len(t.ratios) >= TILT_MIN_COUNT:
                return statistics.median(t.ratios)
        return None

    def verdict(self) -> Verdict:
        return self._verdict

    def _judge(self) -> Verdict:
        slip = self.slip()
        if slip is None:  # (a slip found holds until the tilts agree with rad/s: no flapping on a scatter)
            return self._verdict if self._verdict.untrusted and not self.right_unit() else Verdict(self.NAME)
        r = self.ratio
        return Verdict(self.NAME, Level.ERROR,
                       f"the gyro turns the gravity direction {r:.3g} times as far as the accelerometer shows it turn "
                       f"(median of the last tilts: {slip[0]}?): imu/data_raw's angular_velocity must be rad/s "
                       "(REP-145); fix the driver's unit. The orientation is not to be trusted (covariance: σ 180°)",
                       untrusted=True)
