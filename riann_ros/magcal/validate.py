"""Validation by physics: whether numbers are a calibration a magnetometer can have (ROS-free).

Every calibration the package takes goes through :func:`refusals` — a saved file (``mag_calibration_file``, read by
:func:`riann_ros.magcal.store.load_calibration`), the parameters ``mag_hard_iron`` / ``mag_soft_iron`` of a node,
``riann-mag-calibrate``'s ``--prior`` and its own result, and the estimate the node's save service writes. It
returns the reasons it is refused (empty: usable), each a sentence that names the rule and its number. The
convention is the node's (:mod:`riann_ros.magcal.records`): the calibrated field is ``m = S (m_raw − h)``.

The rules, and why (docs/magnetometer.md, "Saved once, used at every start"):

* **Hard iron** ``|h| ≤`` :data:`HARD_IRON_MAX_T` (0.933 mT): the package reads no raw field above
  :data:`~riann_ros.magcal.records.USABLE_MAX_T` (1 mT: the online calibration counts such a reading as none —
  saturated, or a magnet at the sensor), so a hard iron must leave room for the Earth's field on top of it in
  every orientation, up to :data:`EARTH_FIELD_MAX_T`. 1 mT lies between the full scale of the narrowest common
  settings (LIS3MDL ±400 µT at ±4 gauss, HMC5883L ±130 µT by default) and that of the widest parts (AK09916
  ±4.9 mT, BMM150 ±1.3 mT in x and y), so a magnetometer with a larger offset is saturated, or not read, in some
  orientations whatever its calibration says.
* **Soft iron** symmetric positive definite, up to the magnetometer's misalignment: ``S = U P`` (the polar
  decomposition: ``P`` symmetric positive definite, ``U`` orthogonal). The field of iron near the sensor is a
  symmetric linear map of the Earth's (``P``); the ``full`` model adds the magnetometer's misalignment to the gyro,
  a small rotation ``U``. ``U`` must be a rotation (``det S > 0``: a reflection turns a right-handed sensor into a
  left-handed one) of at most :data:`MISALIGNMENT_MAX_RAD` (10°): a magnetometer on the IMU's board or in its
  package is aligned within a degree or two (the online calibration's prior σ is 1°), 10° leaves room for a
  separate board mounted by hand, and more is a mounting the frames must say (``diag(−1, −1, 1)``, ``det +1``, is a
  rotation of 180°). ``P``'s eigenvalues — the field's scale along its principal axes — within
  :data:`SOFT_IRON_SCALE_RANGE` (0.2–5): the sensor's own sensitivity is within a few percent, and iron near it
  bends the field by tens of percent; at 5 the raw field along that axis is a fifth of the Earth's (5–13 µT, 10–25
  times the reading noise) and the calibration multiplies its noise fivefold; below 0.2 it shrinks a field five
  times the Earth's, which only a magnet at the sensor makes.
* **Covariance** (12×12 over ``(S, h)``): finite, symmetric and positive semi-definite (to :data:`COVARIANCE_TOL`
  of its own standard deviations), with standard deviations no wider than the values allowed: at most
  :data:`SOFT_IRON_SCALE_RANGE`'s upper end per soft-iron entry and :data:`HARD_IRON_MAX_T` per hard-iron axis (a
  wider σ says nothing a calibration can mean; ``1e308`` is a broken number). The test works on the correlations
  (each entry divided by its two standard deviations, bounded by 1), so a number of any size is judged without
  overflow.
* **Calibrated field**, where readings are at hand (``riann-mag-calibrate``): the typical reading's norm
  ``|S (m_raw − h)|`` (the median) within :data:`FIELD_NORM_RANGE_T` (15–100 µT): the Earth's field is 22–67 µT at
  the surface (:data:`EARTH_FIELD_MIN_T`, :data:`EARTH_FIELD_MAX_T`), and a building's steel changes it by tens of
  percent; a calibration that leaves it far outside does not describe the sensor (a hard iron of another robot, a
  scale in the wrong unit).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from riann_ros.magcal.records import USABLE_MAX_T, UT, MagCalibration

#: T; the Earth's field at the surface, weakest (South Atlantic anomaly) and strongest (near the magnetic poles):
#: IGRF-13, 2020.
EARTH_FIELD_MIN_T = 22e-6
EARTH_FIELD_MAX_T = 67e-6
#: T; the largest hard iron accepted: the raw field the package reads (USABLE_MAX_T) less the strongest Earth field.
HARD_IRON_MAX_T = USABLE_MAX_T - EARTH_FIELD_MAX_T
#: the field's scale along the soft iron's principal axes (the eigenvalues of its symmetric part) accepted.
SOFT_IRON_SCALE_RANGE = (0.2, 5.0)
#: rad; the largest rotation a soft iron may hold (the magnetometer's misalignment to the gyro).
MISALIGNMENT_MAX_RAD = math.radians(10.0)
#: T; the typical calibrated reading's norm accepted: the Earth's 22–67 µT, less a third or half again (steel).
FIELD_NORM_RANGE_T = (15e-6, 100e-6)
#: the covariance's asymmetry and negative eigenvalues tolerated, relative to its standard deviations (a float
#: computation's rounding, far below any real correlation).
COVARIANCE_TOL = 1e-6


def refusals(hard_iron_t: ArrayLike, soft_iron: ArrayLike, covariance: ArrayLike | None = None,
             field_norm_t: float | None = None) -> list[str]:
    """The reasons the calibration ``h`` (T, 3), ``S`` (row-major, 9), its covariance (144, row-major over
    ``(S, h)``; None: none to check) and the typical calibrated reading's norm (T; None: no readings at hand) is
    refused (module docstring); empty when it is usable."""
    out = hard_iron_refusals(hard_iron_t) + soft_iron_refusals(soft_iron)
    if covariance is not None:
        out += covariance_refusals(covariance)
    if field_norm_t is not None:
        out += field_norm_refusals(field_norm_t)
    return out


def calibration_refusals(cal: MagCalibration, field_norm_t: float | None = None) -> list[str]:
    """:func:`refusals` of a calibration record."""
    return refusals(cal.hard_iron_t, cal.soft_iron, cal.covariance, field_norm_t)


def _floats(values: ArrayLike, n: int, what: str) -> tuple[NDArray[np.float64] | None, list[str]]:
    try:
        a = np.asarray(values, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        return None, [f"{what} must be {n} numbers"]
    if a.size != n:
        return None, [f"{what} must be {n} numbers, got {a.size}"]
    if not np.isfinite(a).all():
        return None, [f"{what} must hold finite numbers"]
    return a, []


def hard_iron_refusals(hard_iron_t: ArrayLike) -> list[str]:
    """Why the hard iron (T, 3) is refused: not 3 finite numbers, or over :data:`HARD_IRON_MAX_T`."""
    h, out = _floats(hard_iron_t, 3, "mag_hard_iron")
    if h is None:
        return out
    norm = float(np.linalg.norm(h))
    if norm > HARD_IRON_MAX_T:
        return [f"mag_hard_iron |h| = {norm / UT:.4g} µT is over {HARD_IRON_MAX_T / UT:.0f} µT: with the Earth's field "
                f"on top, readings would exceed the {USABLE_MAX_T / UT:.0f} µT the package reads (a field in another "
                "unit, or not a hard iron)"]
    return []


def soft_iron_refusals(soft_iron: ArrayLike) -> list[str]:
    """Why the soft iron (row-major, 9) is refused: not symmetric positive definite up to a rotation of
    :data:`MISALIGNMENT_MAX_RAD`, or scales outside :data:`SOFT_IRON_SCALE_RANGE` (module docstring)."""
    flat, out = _floats(soft_iron, 9, "mag_soft_iron")
    if flat is None:
        return out
    s = flat.reshape(3, 3)
    w, scales, vt = np.linalg.svd(s)  # S = U P with U = W Vᵀ, P = V diag(scales) Vᵀ
    lo, hi = SOFT_IRON_SCALE_RANGE
    det = float(np.linalg.det(s))
    if not det > 0.0:
        out.append("mag_soft_iron is singular (det S = 0)" if det == 0.0 else
                   f"mag_soft_iron is a reflection (det S = {det:.3g} < 0): it would make the sensor left-handed")
    else:
        u = w @ vt
        angle = math.acos(min(1.0, max(-1.0, 0.5 * (float(np.trace(u)) - 1.0))))
        if angle > MISALIGNMENT_MAX_RAD:
            out.append(f"mag_soft_iron holds a rotation of {math.degrees(angle):.1f}° (at most "
                       f"{math.degrees(MISALIGNMENT_MAX_RAD):.0f}°, the magnetometer's misalignment): a soft iron is "
                       "symmetric positive definite")
    if scales.min() < lo or scales.max() > hi:
        out.append(f"mag_soft_iron scales the field by {scales.min():.4g}–{scales.max():.4g} along its principal "
                   f"axes, outside {lo:g}–{hi:g}")
    return out


def covariance_refusals(covariance: ArrayLike) -> list[str]:
    """Why the covariance (144, row-major 12×12 over ``(S, h)``) is refused: not finite, not bounded, not symmetric
    positive semi-definite (module docstring)."""
    flat, out = _floats(covariance, 144, "covariance")
    if flat is None:
        return out
    c = flat.reshape(12, 12)
    var = np.diag(c)
    if (var < 0.0).any():
        return ["covariance is not positive semi-definite (a negative variance)"]
    sd = np.sqrt(var)
    limits = np.r_[np.full(9, SOFT_IRON_SCALE_RANGE[1]), np.full(3, HARD_IRON_MAX_T)]
    if (sd > limits).any():
        return [f"covariance: a standard deviation is over its bound ({SOFT_IRON_SCALE_RANGE[1]:g} per soft-iron "
                f"entry, {HARD_IRON_MAX_T / UT:.0f} µT per hard-iron axis): a number, not an uncertainty"]
    scale = np.where(sd > 0.0, sd, 1.0)
    with np.errstate(over="ignore", invalid="ignore"):
        k = c / np.outer(scale, scale)  # the correlations (|k| <= 1 for a covariance)
    if not (np.isfinite(k).all() and np.abs(k).max() <= 1.0 + COVARIANCE_TOL):
        return ["covariance is not positive semi-definite (an entry exceeds what its variances allow)"]
    if np.abs(k - k.T).max() > COVARIANCE_TOL:
        return ["covariance is not symmetric"]
    try:
        smallest = float(np.linalg.eigvalsh(0.5 * (k + k.T))[0])
    except np.linalg.LinAlgError:
        return ["covariance: its eigenvalues cannot be computed"]
    if smallest < -COVARIANCE_TOL:
        return ["covariance is not positive semi-definite"]
    return []


def field_norm_refusals(field_norm_t: float) -> list[str]:
    """Why the typical calibrated reading's norm (T) is refused: outside :data:`FIELD_NORM_RANGE_T`."""
    lo, hi = FIELD_NORM_RANGE_T
    if not lo <= field_norm_t <= hi:
        return [f"the calibrated field |m| = {field_norm_t / UT:.4g} µT (the median reading) is outside "
                f"{lo / UT:.0f}–{hi / UT:.0f} µT (the Earth's field is {EARTH_FIELD_MIN_T / UT:.0f}–"
                f"{EARTH_FIELD_MAX_T / UT:.0f} µT): it does not describe this sensor"]
    return []


def typical_field_norm_t(hard_iron_t: ArrayLike, soft_iron: ArrayLike, raw_t: ArrayLike) -> float | None:
    """T; the median of ``|S (m_raw − h)|`` over the finite rows of ``raw_t`` (N, 3; T); None without any."""
    raw = np.asarray(raw_t, dtype=float).reshape(-1, 3)
    raw = raw[np.isfinite(raw).all(axis=1)]
    if not len(raw):
        return None
    s = np.asarray(soft_iron, dtype=float).reshape(3, 3)
    return float(np.median(np.linalg.norm((raw - np.asarray(hard_iron_t, dtype=float)) @ s.T, axis=1)))
