"""Windows of rotation: the per-sample part of the calibration, in plain floats (ROS-free).

A world-fixed field seen from a turning sensor: with the sensor's attitude ``q`` (sensor → world) and the gyro's
rotation ``P`` from a window's first reading to its last (``q_end = q_start ⊗ P``), the calibrated readings satisfy
``u_start = R(P) u_end``. :class:`Windower` accumulates ``P`` from the bias-corrected gyro increments (one
quaternion product per sample) and closes a window once the sensor has turned :data:`WINDOW_ANGLE_RAD`. A motion
that swings back before that (a wobble, a robot's small turns) closes it at the farthest reading of the swing once
the sensor has come back :data:`TURN_BACK_RAD` from it, if that reading is at least :data:`WINDOW_MIN_ANGLE_RAD` from
the start (the swing's end is where the window's angle is largest and the sensor slowest); so does
:data:`WINDOW_MAX_S`, and a window that has not turned :data:`WINDOW_MIN_ANGLE_RAD` by then is dropped (at rest and
in straight motion no window closes, so nothing moves). The next window starts at the next reading, so no two
windows share a reading and their noises are independent.

The magnetometer's latency ``D`` (the front end's latency fit estimates it, :mod:`.latency`): a reading stamped ``t``
saw the field at ``t − D``, so each end of a window takes the gyro attitude of ``t − D``, interpolated in a short
history of the integrated attitude (only at a window's ends).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from riann_ros.magcal.records import (
    DELAY_SD_S,
    MAX_DELAY_S,
    MAX_STEP_S,
    WINDOW_ANGLE_RAD,
    WINDOW_MAX_S,
    WINDOW_MIN_ANGLE_RAD,
)
from riann_ros.rotations import IDENTITY, Quat, Vec, conj, normalized, qmul

_COS_HALF = math.cos(0.5 * WINDOW_ANGLE_RAD)
_COS_HALF_MIN = math.cos(0.5 * WINDOW_MIN_ANGLE_RAD)
#: rad; a window whose sensor has come back this far from its farthest reading closes there (module docstring): far
#: more than the gyro noise over a swing, small against the least window angle.
TURN_BACK_RAD = 5.0 * math.pi / 180.0


@dataclass(frozen=True)
class Window:
    """One window's constraint data: the raw readings at its ends (µT), the gyro rotation between them
    (``q_end = q_start ⊗ rot``), its length (s), angle (rad), the rotation rates at its ends (rad/s) and the
    standard deviation of the latency its ends were taken at (s)."""

    m0_ut: Vec
    m1_ut: Vec
    rot: Quat
    duration_s: float
    angle_rad: float
    rate0_rad_s: float
    rate1_rad_s: float
    delay_sd_s: float = DELAY_SD_S


@dataclass(frozen=True)
class WindowSet:
    """Windows as arrays (W rows): :class:`Window`'s fields stacked (``rot`` (W, 4))."""

    m0_ut: NDArray[np.float64]
    m1_ut: NDArray[np.float64]
    rot: NDArray[np.float64]
    duration_s: NDArray[np.float64]
    angle_rad: NDArray[np.float64]
    rate0_rad_s: NDArray[np.float64]
    rate1_rad_s: NDArray[np.float64]
    delay_sd_s: NDArray[np.float64]

    @classmethod
    def of(cls, windows: list[Window]) -> WindowSet:
        def col(name: str) -> NDArray[np.float64]:
            return np.array([getattr(w, name) for w in windows], dtype=float)

        return cls(col("m0_ut").reshape(-1, 3), col("m1_ut").reshape(-1, 3), col("rot").reshape(-1, 4),
                   col("duration_s"), col("angle_rad"), col("rate0_rad_s"), col("rate1_rad_s"), col("delay_sd_s"))

    def __len__(self) -> int:
        return len(self.duration_s)


def _rate(delta: Quat, dt: float) -> float:
    s = math.sqrt(delta[1] * delta[1] + delta[2] * delta[2] + delta[3] * delta[3])
    return 2.0 * math.atan2(s, abs(delta[0])) / dt if dt > 0.0 else 0.0


def _angle(q: Quat) -> float:
    return 2.0 * math.acos(min(1.0, abs(q[0])))


class Windower:
    """Cuts the stream into windows (see the module docstring); :meth:`add` per sample."""

    def __init__(self) -> None:
        self.t = 0.0  # s since the first sample
        self.q: Quat = IDENTITY  # the integrated gyro attitude (relative to the first sample)
        #: (t, q) of the last MAX_DELAY_S (or of the latency, when a late field's is longer: the lag scan's)
        self.hist: deque[tuple[float, Quat]] = deque()
        self.open = False
        self.m0: Vec = (0.0, 0.0, 0.0)
        self.q0: Quat = IDENTITY  # the attitude the window's first reading saw
        self.qa: Quat = IDENTITY  # the attitude at the window's first sample (for the angle test)
        self.t0 = 0.0
        self.rate0 = 0.0
        self.delay_sd = self.delay_sd0 = DELAY_SD_S  # s; the latency's σ now, and at the open window's start
        self.best_angle = 0.0  # rad; the farthest reading of the open window from its start
        self.best: tuple[Vec, Quat, float, float] | None = None  # its (reading, attitude it saw, t, rate)

    def restart(self) -> None:
        """A hole or a reset: the open window is dropped (the rotation across the hole is not known)."""
        self.open = False
        self.hist.clear()

    def _attitude_at(self, t: float) -> Quat:
        """The integrated attitude at time ``t`` (≤ now), interpolated (normalised lerp) in the history."""
        h = self.hist
        if not h or t >= h[-1][0]:
            return self.q
        for i in range(len(h) - 1, 0, -1):
            ta, qa = h[i - 1]
            if ta <= t:
                tb, qb = h[i]
                f = (t - ta) / (tb - ta) if tb > ta else 1.0
                return normalized(tuple(a + f * (b - a) for a, b in zip(qa, qb, strict=True)))  # type: ignore[arg-type]
        return h[0][1]

    def add(self, delta: Quat, dt: float, mag_ut: Vec | None, delay_s: float = 0.0,
            delay_sd_s: float = DELAY_SD_S) -> Window | None:
        """One sample: ``delta`` its bias-corrected gyro increment (sensor frame, ``q_k = q_{k−1} ⊗ delta``), ``dt``
        its step (s), ``mag_ut`` its raw reading (µT, finite) or None, ``delay_s`` the magnetometer's latency and
        ``delay_sd_s`` its standard deviation. Returns the window this sample closes, or None."""
        self.delay_sd = delay_sd_s
        if not 0.0 < dt <= MAX_STEP_S:
            self.restart()
            return None
        self.t += dt
        self.q = qmul(self.q, delta)
        if delay_s > 0.0:
            self.hist.append((self.t, self.q))
            while len(self.hist) > 2 and self.hist[1][0] < self.t - max(MAX_DELAY_S, delay_s):
                self.hist.popleft()
            if self.hist[0][0] > self.t - delay_s:  # the reading saw an attitude before the history (the first
                mag_ut = None  # samples, after a hole, or a calibration restarted at a late field's lag): unknown
        if not self.open:
            if mag_ut is not None:
                self._start(mag_ut, delta, dt, delay_s)
            return None
        if mag_ut is None:
            if self.t - self.t0 >= WINDOW_MAX_S + 1.0:  # no reading for a long time: start over at the next one
                self.open = False
            return None
        return self._reading(mag_ut, delta, dt, delay_s)

    def _reading(self, mag_ut: Vec, delta: Quat, dt: float, delay_s: float) -> Window | None:
        """A reading while a window is open: it closes the window (at 45°, or at a swing's end), becomes the swing's
        farthest, or starts over a window that timed out without turning."""
        qa = self.qa
        q = self.q
        c = abs(qa[0] * q[0] + qa[1] * q[1] + qa[2] * q[2] + qa[3] * q[3])  # cos(angle/2) since the start
        timed = self.t - self.t0 >= WINDOW_MAX_S
        if c <= _COS_HALF:
            return self._close(mag_ut, self._reading_attitude(delay_s), _rate(delta, dt))
        angle = 2.0 * math.acos(min(1.0, c))
        if angle > self.best_angle:  # still turning away from the start
            self.best_angle = angle
            if angle >= WINDOW_MIN_ANGLE_RAD:
                self.best = (mag_ut, self._reading_attitude(delay_s), self.t, _rate(delta, dt))
                if timed:  # a slow turn: the window closes here, the next reading starts the next one
                    return self._close(*self.best[:2], self.best[3])
        elif self.best is not None and (timed or angle <= self.best_angle - TURN_BACK_RAD):
            m, q1, t1, rate1 = self.best  # the swing's end: the window closes there, the next one starts here
            w = self._close(m, q1, rate1, t1)
            self._start(mag_ut, delta, dt, delay_s)
            return w
        if timed:  # timed out without turning enough: no information, start over here
            self._start(mag_ut, delta, dt, delay_s)
        return None

    def _reading_attitude(self, delay_s: float) -> Quat:
        """The integrated attitude the current sample's reading saw (``delay_s`` earlier)."""
        return self._attitude_at(self.t - delay_s) if delay_s > 0.0 else self.q

    def _start(self, m: Vec, delta: Quat, dt: float, delay_s: float) -> None:
        self.open = True
        self.m0 = m
        self.qa = self.q
        self.q0 = self._reading_attitude(delay_s)
        self.t0 = self.t
        self.rate0 = _rate(delta, dt)
        self.delay_sd0 = self.delay_sd
        self.best_angle, self.best = 0.0, None

    def _close(self, m: Vec, q1: Quat, rate1: float, t1: float | None = None) -> Window:
        """The window from the start to the reading ``m`` (the attitude ``q1`` it saw, the rate ``rate1`` then, at
        time ``t1``: now when None)."""
        rot = normalized(qmul(conj(self.q0), q1))
        w = Window(self.m0, m, rot, (self.t if t1 is None else t1) - self.t0, _angle(rot), self.rate0, rate1,
                   max(self.delay_sd0, self.delay_sd))
        self.open = False
        self.q = normalized(self.q)
        return w
