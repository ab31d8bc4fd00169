"""The offline calibration of one recording, with what a user checks it by (ROS-free; ``riann-mag-calibrate``).

:func:`calibrate_recording` takes a whole :class:`~riann_ros.recording.Recording` with its magnetometer and what
its gyro and accelerometer say of its motion (:class:`GyroMotion`: the gyro with its bias removed the way the
estimators do, and a 6D attitude; :func:`riann_ros.estimators.motion.gyro_motion` makes it), fits hard and soft iron
over all of it (:func:`~.offline.fit_recording`) and measures the result two ways:

* **the sphere**: the calibrated readings' norm (the field's strength) is the same in every orientation; its spread
  against the raw readings' shows what the calibration removed;
* **the heading before and after**: the direction of magnetic north in a frame the gyro carries (VQF's 6D
  attitude: tilt from the accelerometer, heading from the integrated gyro, no magnetometer). A world-fixed field seen
  through a correct calibration points the same way however the sensor turns, so that direction stays put up to the
  gyro's slow drift; through a hard-iron offset it swings with the orientation. The figure is the RMS of its
  deviation from a straight line over time (the drift), in degrees.

**The magnetometer's latency** behind the gyro matters in fast rotation: a reading taken ``τ`` before its stamp is
rotated by ``ωτ`` against the gyro's attitude, which the fit reads as a hard iron across the rotation axis (BROAD
trial 07, fast rotation: the vertical hard iron off by 11.7 µT at τ = 0, by 2.3 µT at 10 ms). Unless it is given,
:func:`estimate_delay` takes the latency whose fit leaves the least residual (RMS over the windows): on a 10 ms grid
over 0–100 ms (the range RIANN's online latency estimate allows), then a golden-section search around the best to
1 ms, each a batch fit of at most :data:`SEARCH_WINDOWS` windows. Without rotation the residual does not depend on
it (nothing is biased either).

Readings are used once: a reading repeated on the following IMU samples (a magnetometer slower than the IMU, paired
the nodes' way, :mod:`riann_ros.magcal.input`) counts at the first of them only.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from riann_ros import quaternion as quat
from riann_ros.bagio.layout import MAG_TOPIC
from riann_ros.magcal.heading import heading_angles
from riann_ros.magcal.offline import OfflineFit, fit_recording, fit_windows, windows_of
from riann_ros.magcal.records import HARD_IRON_PRIOR_SD_T, MAX_DELAY_S, UT, MagCalPrior, SoftIronModel
from riann_ros.recording import Recording

Array = NDArray[np.float64]

#: a hard-iron axis whose σ after the fit is above this fraction of its prior σ was not observed (the sensor did not
#: turn about the axes across it); the node keeps calibrating it online from the saved estimate.
UNOBSERVED_FRACTION = 0.5


DELAY_STEP_S = 0.01  # the latency search's grid
DELAY_TOL_S = 0.001  # ... and its resolution (the latency's effect: ω × 1 ms × |B|, 0.2 µT at 4 rad/s and 50 µT)
SEARCH_WINDOWS = 4000  # windows per fit of the search at most (evenly spread over the recording)
GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0


class NotCalibratable(ValueError):
    """A recording that gives nothing to calibrate from (no magnetometer, no plausible reading, no rotation)."""


class NoMagnetometer(NotCalibratable):
    """A recording without a magnetometer."""


@dataclass(frozen=True)
class GyroMotion:
    """What a recording's gyro and accelerometer say of its motion, per sample: the gyro with its bias removed
    (rad/s, (N, 3)) and an attitude without the magnetometer (sensor → world, (N, 4): tilt from the accelerometer,
    heading from the integrated gyro)."""

    gyr: Array
    attitude: Array


@dataclass(frozen=True)
class RecordingFit:
    """The fit of one recording and its checks: readings' times (s), raw and calibrated fields (µT, one row per
    fresh plausible reading), the direction of north in the gyro-carried frame for both (rad), and the spread
    figures (module docstring)."""

    fit: OfflineFit
    seconds: float
    t: Array
    raw_ut: Array
    cal_ut: Array
    north_raw_rad: Array
    north_cal_rad: Array
    unobserved_axes: tuple[str, ...]
    delay_s: float = 0.0  # the magnetometer's latency the fit used
    delay_estimated: bool = False  # by estimate_delay (else given)

    @property
    def readings(self) -> int:
        return len(self.t)

    @property
    def north_spread_raw_deg(self) -> float:
        return _spread_deg(self.t, self.north_raw_rad)

    @property
    def north_spread_cal_deg(self) -> float:
        return _spread_deg(self.t, self.north_cal_rad)

    @property
    def norm_sd_raw_ut(self) -> float:
        return float(np.std(np.linalg.norm(self.raw_ut, axis=1))) if self.readings else 0.0


def _spread_deg(t: Array, north: Array) -> float:
    """RMS (°) of the unwrapped direction's deviation from its straight-line fit over time."""
    if len(t) < 3:
        return 0.0
    u = np.unwrap(north)
    a = np.vstack([t, np.ones_like(t)]).T
    resid = u - a @ np.linalg.lstsq(a, u, rcond=None)[0]
    return math.degrees(float(np.sqrt(np.mean(resid * resid))))


def fresh_readings(mag: Array) -> NDArray[np.bool_]:
    """Rows of a paired field (N, 3) that hold a reading not already on the previous row (NaN rows: none)."""
    ok: NDArray[np.bool_] = np.asarray(np.isfinite(mag).all(axis=1))
    same = np.zeros(len(mag), dtype=bool)
    same[1:] = ok[1:] & ok[:-1] & np.all(mag[1:] == mag[:-1], axis=1)
    return ok & ~same


def _north(q: Array, field: Array) -> Array:
    """The heading (rad, from world +y toward +x: magnetic north in ENU) of ``field`` (sensor frame) at ``q``."""
    return heading_angles(quat.rotate(q, field))


def residual_rms_ut(gyr: Array, dt: Array, mag_t: Array, delay_s: float, prior: MagCalPrior | None = None,
                    soft_iron_model: SoftIronModel = "full") -> float:
    """The RMS residual (µT) of a batch fit of the windows at ``delay_s`` (inf without windows)."""
    ws, overlap = windows_of(gyr, dt, mag_t, delay_s, max_windows=SEARCH_WINDOWS)
    if not len(ws):
        return math.inf
    model, theta, *_ = fit_windows(ws, overlap, prior, soft_iron_model)
    j, r0 = model.rows(ws)
    r = r0 + j @ theta
    return float(np.sqrt(np.mean(r * r)))


def estimate_delay(gyr: Array, dt: Array, mag_t: Array, prior: MagCalPrior | None = None,
                   soft_iron_model: SoftIronModel = "full") -> float:
    """The magnetometer's latency behind the gyro (s) that leaves the least residual (module docstring); ``gyr``
    bias-corrected (N, 3), ``mag_t`` raw (N, 3) T with NaN rows where no reading."""

    def cost(d: float) -> float:
        return residual_rms_ut(gyr, dt, mag_t, d, prior, soft_iron_model)

    grid = np.arange(0.0, MAX_DELAY_S + 0.5 * DELAY_STEP_S, DELAY_STEP_S)
    costs = [cost(float(d)) for d in grid]
    k = int(np.argmin(costs))
    if not math.isfinite(costs[k]):
        return 0.0
    lo, hi = float(grid[max(k - 1, 0)]), float(grid[min(k + 1, len(grid) - 1)])
    a, b = hi - GOLDEN * (hi - lo), lo + GOLDEN * (hi - lo)
    fa, fb = cost(a), cost(b)
    while hi - lo > DELAY_TOL_S:
        if fa <= fb:
            hi, b, fb = b, a, fa
            a = hi - GOLDEN * (hi - lo)
            fa = cost(a)
        else:
            lo, a, fa = a, b, fb
            b = lo + GOLDEN * (hi - lo)
            fb = cost(b)
    best = min(((costs[k], float(grid[k])), (fa, a), (fb, b)))
    return round(best[1], 4)


def calibrate_recording(rec: Recording, motion: Callable[[Recording], GyroMotion], prior: MagCalPrior | None = None,
                        soft_iron_model: SoftIronModel = "full", delay_s: float | None = None) -> RecordingFit:
    """Fit the calibration of ``rec`` (module docstring), ``motion`` what gives its gyro and attitude
    (:func:`riann_ros.estimators.motion.gyro_motion`; called once the recording has readings to fit), with the
    magnetometer's latency ``delay_s`` (s; None: :func:`estimate_delay`); :class:`NotCalibratable` when there is
    nothing to fit."""
    from riann_ros.magcal.input import plausible

    if rec.mag is None:
        raise NoMagnetometer(f"no magnetometer in the recording (in a bag: no sensor_msgs/msg/MagneticField on "
                             f"{MAG_TOPIC})")
    mag = np.where(fresh_readings(rec.mag)[:, None], rec.mag, np.nan)
    ok = plausible(mag)
    if not ok.any():
        raise NotCalibratable("no plausible magnetometer reading (all missing, or norms outside the Earth's field "
                              "range: a field in µT or gauss stored as tesla?)")
    dt = rec.dt
    moved = motion(rec)
    gyr = moved.gyr
    delay = estimate_delay(gyr, dt, mag, prior, soft_iron_model) if delay_s is None else delay_s
    fit = fit_recording(gyr, dt, mag, prior=prior, soft_iron_model=soft_iron_model, delay_s=delay, acc=rec.acc)
    if fit.windows == 0:
        raise NotCalibratable("the sensor never turned 15° within 5 s: no rotation to calibrate from (turn the "
                              "robot, or the sensor, through several headings while recording)")
    cal = fit.calibration
    s = np.asarray(cal.soft_iron).reshape(3, 3)
    h = np.asarray(cal.hard_iron_t) / UT
    q = moved.attitude[ok]
    raw = mag[ok] / UT
    calibrated = (raw - h) @ s.T
    prior_sd = (prior.hard_iron_sd_t if prior is not None and prior.covariance is None else HARD_IRON_PRIOR_SD_T)
    unobserved = tuple(ax for ax, sd in zip("xyz", cal.hard_iron_sd_t, strict=True)
                       if sd > UNOBSERVED_FRACTION * prior_sd)
    return RecordingFit(fit=fit, seconds=float(rec.t[-1]), t=rec.t[ok], raw_ut=raw, cal_ut=calibrated,
                        north_raw_rad=_north(q, raw), north_cal_rad=_north(q, calibrated),
                        unobserved_axes=unobserved, delay_s=delay, delay_estimated=delay_s is None)
