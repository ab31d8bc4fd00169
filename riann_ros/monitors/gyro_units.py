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
there. With :data:`~riann_ros.datasets.units.TILT_MIN_COUNT` tilts the verdict is the median of the last
:data:`KEEP` ratios: outside a factor :data:`~riann_ros.datasets.units.TILT_RATIO_TOL` of 1 the gyro is in another
unit, an ERROR, and the estimate is not to be trusted (every σ half a turn) for as long as the tilts say so.

Rotation about the vertical alone does not move the gravity direction: a ground robot that only turns is not tested
(the verdict stays OK).
"""

from __future__ import annotations

import math
import statistics
from collections import deque

from riann_ros.datasets.gyro_tilt import BIAS_MAX_DEG_S, COS_MIN, LOWPASS_S, STATIC_TOL, TILT_MIN_DEG, WINDOWS_S
from riann_ros.datasets.units import TILT_MIN_COUNT, TILT_RATIO_TOL
from riann_ros.gate import G_CHECK_SAMPLES
from riann_ros.monitors.base import Level, Verdict

#: the last this many tilts' ratios make the verdict (a unit fixed at run time clears it within as many tilts)
KEEP = 9
#: s; the first-order low-pass of the accelerometer (the converter's centred mean of LOWPASS_S, causal)
LOWPASS_TAU_S = LOWPASS_S / 2.0
#: s; a tilt longer than the converter's longest window starts anew (the bias's drift)
MAX_TILT_S = WINDOWS_S[-1]
_TILT_MIN = math.radians(TILT_MIN_DEG)
_BIAS_MAX = math.radians(BIAS_MAX_DEG_S)


class GyroUnitsMonitor:
    """The gyro's unit against the accelerometer's tilt rate (module docstring); :meth:`step` per accepted sample."""

    NAME = "gyro units"

    def __init__(self) -> None:
        self.ratios: deque[float] = deque(maxlen=KEEP)
        self.tilts = 0  # tilts measured in all
        self.restart()

    def restart(self) -> None:
        """A (re)start of the stream: the low-pass, the open tilt and the ``|acc|`` at rest anew (the median of the
        first :data:`~riann_ros.gate.G_CHECK_SAMPLES` samples, in the accelerometer's own unit, as the gate's
        g-units check takes it). The ratios are kept (the same sensor)."""
        self.acc_rest: float | None = None
        self._norms: list[float] = []
        self.lp: tuple[float, float, float] | None = None
        self.u0: tuple[float, float, float] | None = None  # the open tilt's anchor
        self.turn = (0.0, 0.0, 0.0)  # ∫ u × ω dt since the anchor
        self.t = 0.0

    def step(self, ax: float, ay: float, az: float, gx: float, gy: float, gz: float, dt: float) -> None:
        """One accepted sample (acc in any unit, gyr as read, dt s)."""
        if self.acc_rest is None:
            self._norms.append(math.sqrt(ax * ax + ay * ay + az * az))
            if len(self._norms) == G_CHECK_SAMPLES:
                self.acc_rest = statistics.median(self._norms)
        if self.lp is None:
            self.lp = (ax, ay, az)
        else:
            k = dt / (LOWPASS_TAU_S + dt) if dt > 0.0 else 0.0
            lx, ly, lz = self.lp
            self.lp = (lx + k * (ax - lx), ly + k * (ay - ly), lz + k * (az - lz))
        lx, ly, lz = self.lp
        n = math.sqrt(lx * lx + ly * ly + lz * lz)
        if not (0.0 < n < math.inf and self.acc_rest):
            return
        ux, uy, uz = lx / n, ly / n, lz / n
        static = abs(n / self.acc_rest - 1.0) < STATIC_TOL
        if self.u0 is None:
            if static:
                self.u0, self.turn, self.t = (ux, uy, uz), (0.0, 0.0, 0.0), 0.0
            return
        bx, by, bz = self.turn
        self.turn = (bx + (uy * gz - uz * gy) * dt, by + (uz * gx - ux * gz) * dt, bz + (ux * gy - uy * gx) * dt)
        self.t += dt
        if self.t > MAX_TILT_S:
            self.u0 = (ux, uy, uz) if static else None
            self.turn, self.t = (0.0, 0.0, 0.0), 0.0
            return
        if static:
            self._close(ux, uy, uz)

    def _close(self, ux: float, uy: float, uz: float) -> None:
        """A quasi-static sample: the tilt since the anchor is taken if it turned far enough (module docstring)."""
        assert self.u0 is not None
        x0, y0, z0 = self.u0
        c = max(-1.0, min(1.0, x0 * ux + y0 * uy + z0 * uz))
        if math.acos(c) < max(_TILT_MIN, 2.0 * _BIAS_MAX * self.t):
            return
        a = (ux - x0, uy - y0, uz - z0)
        b = self.turn
        na = math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
        nb = math.sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2])
        if a[0] * b[0] + a[1] * b[1] + a[2] * b[2] >= COS_MIN * na * nb and na > 0.0:
            self.ratios.append(nb / na)
            self.tilts += 1
        self.u0, self.turn, self.t = (ux, uy, uz), (0.0, 0.0, 0.0), 0.0

    @property
    def ratio(self) -> float | None:
        """The median ratio gyro / accelerometer of the last tilts (None: fewer than TILT_MIN_COUNT)."""
        return statistics.median(self.ratios) if len(self.ratios) >= TILT_MIN_COUNT else None

    def verdict(self) -> Verdict:
        r = self.ratio
        if r is None or 1.0 / TILT_RATIO_TOL < r < TILT_RATIO_TOL:
            return Verdict(self.NAME)
        hint = (" (deg/s read as rad/s?)" if 30.0 < r < 100.0 else " (mdeg/s or mrad/s?)" if r > 100.0
                else " (a value divided by 9.81?)" if 0.05 < r < 0.2 else "")
        return Verdict(self.NAME, Level.ERROR,
                       f"the gyro turns the gravity direction {r:.3g} times as far as the accelerometer shows it turn "
                       f"(median of {len(self.ratios)} tilts){hint}: imu/data_raw's angular_velocity must be rad/s "
                       "(REP-145); fix the driver's unit. The orientation is not to be trusted (covariance: σ 180°)",
                       untrusted=True)
