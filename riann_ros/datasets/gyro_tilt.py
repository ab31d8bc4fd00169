"""How far the gyro turns the gravity direction against how far the accelerometer sees it turn (ROS-free).

A world-fixed direction seen in the sensor frame turns with the sensor: for the gravity direction ``u`` (the unit
specific force at rest) ``du/dt = u × ω`` exactly. So over any interval the accelerometer's change of ``u`` and the
gyro's integral of ``u × ω`` are the same vector, whatever the rotation and however large; a gyro read in the wrong
unit makes the integral k times as long (k = 57.3 for deg/s read as rad/s, 1000 for mrad/s, 1/57.3 for rad/s read as
deg/s). The accelerometer's scale drops out: only the direction of its reading is used.

:func:`measure` finds the tilts where the accelerometer can show this and gives, per tilt, the ratio
``|∫ u × ω dt| / |Δu|``. The thresholds are physical and unit-free:

* the accelerometer's direction is gravity's only where linear acceleration is small: both ends of a tilt lie where
  the low-passed ``|acc|`` is within :data:`STATIC_TOL` of its value at rest;
* the gravity direction turns by at least :data:`TILT_MIN_DEG` and at least twice what the largest plausible gyro
  bias (:data:`BIAS_MAX_DEG_S`) turns it in the same time, so neither end errors nor bias dominate;
* the gyro's change points the way the accelerometer's does (cosine at least :data:`COS_MIN`): a unit error
  scales the gyro but keeps its direction, while apparent tilts made by linear acceleration have none.

Rotation about the vertical does not move the gravity direction and cannot be tested this way: a recording that
only turns about the vertical gives no tilts. The judgement (which unit fits) is :func:`riann_ros.datasets.units.
check_gyro_tilt`'s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

# The accelerometer is low-passed by a centred moving average over this many seconds before its direction is
# taken: body and robot tilting lies below ~5 Hz, vibration, tapping and sensor noise above ~10 Hz.
LOWPASS_S = 0.1
# "Quasi-static": the low-passed |acc| within 5 % of its value at rest. A horizontal linear acceleration a tilts the
# reading by atan(a/g) and lengthens it by sqrt(1 + (a/g)²): 5 % admits up to ~0.3 g, the direction test below and
# the majority over many tilts (units.check_gyro_tilt) handle the rest.
STATIC_TOL = 0.05
# The tilt must exceed the direction errors of its two ends (a few degrees at quasi-static ends) several times.
TILT_MIN_DEG = 15.0
# Zero-rate offset of an uncalibrated MEMS gyro: typically ±1–3 °/s, ±5 °/s at worst (units.REST_GYR_RAD_S). A tilt
# over T seconds must be at least twice what this bias turns in T, so bias cannot move the ratio by more than ±50 %.
BIAS_MAX_DEG_S = 5.0
# Interval lengths tried from each start (the shortest that tilts enough is taken); the longest bounds bias drift.
WINDOWS_S = (0.25, 0.5, 1.0, 2.0, 4.0)
# Starts are tried every this many seconds.
STEP_S = 0.02
# The gyro's change of the gravity direction within 45° of the accelerometer's.
COS_MIN = 0.7
# A step longer than this many median steps is a hole in the recording: no tilt is taken across it.
HOLE_STEPS = 5.0
# Faster recordings are first averaged in blocks down to at most this rate (the test looks at motion below ~10 Hz).
MAX_RATE_HZ = 200.0
# "Still": quasi-static and the gravity direction within STILL_DEG over STILL_S around the sample (a tilt of 2 °/s
# moves it 1° in that time). While still the sensor turns at most about the vertical, so the gyro's component across
# the gravity direction is its bias (and noise). Measured when at least STILL_MIN_S of such samples exist.
STILL_S = 0.5
STILL_DEG = 1.0
STILL_MIN_S = 0.5


@dataclass(frozen=True)
class Tilts:
    """Non-overlapping tilts of one recording: per tilt the gravity direction's change (deg) and the ratio gyro /
    accelerometer (the gyro in the unit it was read in); ``still_rate``: the median gyro rate across the gravity
    direction while the sensor is still (as read, rad/s; NaN when it is never still long enough), i.e. its bias."""

    tilt_deg: NDArray[np.float64]
    ratio: NDArray[np.float64]
    still_rate: float = math.nan

    def __len__(self) -> int:
        return len(self.ratio)


def _moving_average(x: NDArray[np.float64], n: int) -> NDArray[np.float64]:
    """Centred moving average over ``n`` samples (shorter at the ends)."""
    if n <= 1:
        return x.copy()
    c = np.concatenate([np.zeros((1, x.shape[1])), np.cumsum(x, axis=0)])
    k = np.arange(len(x))
    lo = np.clip(k - n // 2, 0, len(x))
    hi = np.clip(k - n // 2 + n, 0, len(x))
    return (c[hi] - c[lo]) / (hi - lo)[:, None]


def _rest_norm(norm: NDArray[np.float64], fs: float) -> float:
    """|acc| at rest, in the accelerometer's own unit: the median over the steadiest quarter of the samples (the
    smallest change of the low-passed |acc| over :data:`LOWPASS_S`)."""
    n = max(1, round(LOWPASS_S * fs))
    change = np.abs(norm[n:] - norm[:-n]) if len(norm) > n else np.zeros(len(norm))
    steady = change <= np.percentile(change, 25)
    return float(np.median(norm[: len(change)][steady]))


def _first_tilt_end(t: NDArray[np.float64], u: NDArray[np.float64], static: NDArray[np.bool_],
                    holes: NDArray[np.int64], starts: NDArray[np.intp]) -> NDArray[np.intp]:
    """Per start, the end of the shortest window of :data:`WINDOWS_S` that tilts enough between quasi-static ends
    without a hole (-1: none)."""
    end = np.full(len(starts), -1)
    for w in WINDOWS_S:
        e_all = np.searchsorted(t, t[starts] + w)  # the first sample w seconds or more after the start
        idx = np.flatnonzero((e_all < len(t)) & (end < 0))
        s, e = starts[idx], e_all[idx]
        need = math.radians(max(TILT_MIN_DEG, 2.0 * BIAS_MAX_DEG_S * w))
        angle = np.arccos(np.clip(np.einsum("ij,ij->i", u[s], u[e]), -1.0, 1.0))
        ok = static[s] & static[e] & (holes[e] == holes[s]) & (angle >= need)
        end[idx[ok]] = e[ok]
    return end


def measure(stamps_ns: NDArray[np.int64], acc: NDArray[np.float64], gyr: NDArray[np.float64]) -> Tilts:
    """The tilts of a recording where the accelerometer shows the gravity direction turning, and the ratio of the
    gyro's turn (``gyr`` as read, rad/s) to it; non-overlapping, in time order. Non-finite samples are left out."""
    ok = np.isfinite(acc).all(axis=1) & np.isfinite(gyr).all(axis=1)
    t = (np.asarray(stamps_ns)[ok] - (stamps_ns[0] if len(stamps_ns) else 0)) * 1e-9
    acc, gyr = np.asarray(acc, dtype=float)[ok], np.asarray(gyr, dtype=float)[ok]
    empty = Tilts(np.empty(0), np.empty(0))
    if len(t) < 10:
        return empty
    step = float(np.median(np.diff(t)))
    if not step > 0.0:
        return empty
    k = math.ceil(1.0 / (step * MAX_RATE_HZ))
    if k > 1:  # block means: the gyro's integral and the low-passed accelerometer keep their values
        n = len(t) // k * k
        t, acc, gyr = (x[:n].reshape(n // k, k, *x.shape[1:]).mean(axis=1) for x in (t, acc, gyr))
        step *= k
    dt = np.diff(t, prepend=t[0])
    fs = 1.0 / step
    lp = _moving_average(acc, max(1, round(LOWPASS_S * fs)))
    norm = np.linalg.norm(lp, axis=1)
    g = _rest_norm(norm, fs)
    if not g > 0.0:
        return empty
    u = lp / np.maximum(norm, 1e-300)[:, None]
    static = np.abs(norm / g - 1.0) < STATIC_TOL
    holes = np.cumsum(dt > HOLE_STEPS * step, dtype=np.int64)
    gyro_turn = np.concatenate([np.zeros((1, 3)), np.cumsum(np.cross(u, gyr) * dt[:, None], axis=0)])
    starts = np.arange(0, len(t), max(1, round(STEP_S * fs)))
    end = _first_tilt_end(t, u, static, holes, starts)
    i, j = starts[end >= 0], end[end >= 0]
    a = u[j] - u[i]  # the accelerometer's change of the gravity direction
    b = gyro_turn[j + 1] - gyro_turn[i + 1]  # ∫ u × ω dt over samples i+1 … j
    na, nb = np.linalg.norm(a, axis=1), np.linalg.norm(b, axis=1)
    along = np.einsum("ij,ij->i", a, b) >= COS_MIN * na * nb
    i, j, na, nb = i[along], j[along], na[along], nb[along]
    keep, last = [], -1
    for m in range(len(i)):  # non-overlapping: each tilt starts where the previous one ended or later
        if i[m] >= last:
            keep.append(m)
            last = int(j[m])
    sel = np.asarray(keep, dtype=int)
    tilt = np.degrees(2.0 * np.arcsin(np.clip(na[sel] / 2.0, 0.0, 1.0)))
    gyr_lp = _moving_average(gyr, max(1, round(LOWPASS_S * fs)))
    return Tilts(tilt, nb[sel] / na[sel], _still_rate(t, u, static, gyr_lp))


def _still_rate(t: NDArray[np.float64], u: NDArray[np.float64], static: NDArray[np.bool_],
                gyr_lp: NDArray[np.float64]) -> float:
    """The median |low-passed gyro across u| over the still samples (NaN: fewer than :data:`STILL_MIN_S` of them)."""
    lo = np.searchsorted(t, t - STILL_S / 2)
    hi = np.searchsorted(t, t + STILL_S / 2, side="right") - 1
    whole = (t - t[lo] >= 0.9 * STILL_S / 2) & (t[hi] - t >= 0.9 * STILL_S / 2)  # a full span around the sample
    steady = np.einsum("ij,ij->i", u[lo], u[hi]) >= math.cos(math.radians(STILL_DEG))
    still = static & whole & steady & static[lo] & static[hi]
    if still.sum() * float(np.median(np.diff(t))) < STILL_MIN_S:
        return math.nan
    across = gyr_lp[still] - np.einsum("ij,ij->i", gyr_lp[still], u[still])[:, None] * u[still]
    return float(np.median(np.linalg.norm(across, axis=1)))
