"""Physical plausibility of a recording's units (ROS-free): sample rate, gravity at rest, gyro range, the gyro
against the accelerometer, magnetic field.

A CSV log in ms / g / deg/s read with the defaults (s / m/s² / rad/s) still makes a valid-looking
recording: 0.1 Hz, |acc| ≈ 1 at rest, rotation rates of hundreds of "rad/s". :func:`check_units` measures
a few numbers from the recording and returns a :class:`Finding` for each one that no IMU could produce,
with the unit that would make it plausible when there is one. Slow motion in deg/s stays within any gyro's range;
there the gyro is tested against the accelerometer (:func:`check_gyro_tilt`): where the sensor tilts, the gyro
must turn the gravity direction as far as the accelerometer sees it turn. It decides nothing: the converter refuses
to write (or warns with ``--force-units``), and other tools can reuse it on any :class:`Recording`.

The thresholds come from sensor physics; each constant below says why.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from riann_ros.constants import DEG, GRAVITY, NS_PER_S
from riann_ros.datasets.gyro_tilt import BIAS_MAX_DEG_S
from riann_ros.datasets.gyro_tilt import measure as measure_tilts
from riann_ros.recording import Recording

# Sample rate. MEMS IMUs and the attitude filters here run at tens of Hz to a few kHz (BROAD 286 Hz,
# EuRoC 200 Hz, ArduPilot/PX4 logs 100 Hz – 1 kHz, high-rate gyros up to 8 kHz). Below 1 Hz a gyroscope
# cannot follow human or robot motion (its content reaches 10–20 Hz), and above 10 kHz are only the raw
# outputs of a few gyros (e.g. 32 kHz), never a log meant for attitude estimation. Four decades of margin
# against unit factors of 1000: a wrong time unit lands at least a factor 1000 outside a typical rate.
RATE_MIN_HZ = 1.0
RATE_MAX_HZ = 10_000.0
# When two time units both give a rate inside the range (a 2 Hz log in ms could be 2 kHz in us), the
# suggestion is the one nearest (in log scale) to this typical IMU rate.
TYPICAL_RATE_HZ = 200.0

# Gravity. At rest an accelerometer measures |specific force| = g, 9.78 (equator) – 9.83 (poles) m/s².
# Consumer MEMS accelerometers add up to ≈ ±3 % sensitivity error and ±0.1 g offset per axis before
# calibration (≈ ±1.5 m/s² on the norm at worst); 7–13 m/s² leaves room for that and for small motion in
# the "rest" samples, while a wrong unit is off by a factor 9.8 (g ↔ m/s²).
ACC_REST_MIN = 7.0
ACC_REST_MAX = 13.0
# "At rest" = |gyr| below this, in rad/s (≈ 11 °/s): above the zero-rate offset of uncalibrated MEMS gyros
# (typically ±1–3 °/s, ±5 °/s at worst) plus noise, and below deliberate hand, body or robot motion (tens
# to hundreds of °/s). Fewer than REST_MIN_SAMPLES such samples (never still, or a gyro in the wrong
# unit) → the median |acc| is taken over all samples, which for human and robot motion stays near g too
# (BROAD trials: 9.8–9.95 m/s²).
REST_GYR_RAD_S = 0.2
REST_MIN_SAMPLES = 10

# Gyroscope range. MEMS gyros have full-scale ranges of ±125 … ±2000 °/s (a few reach ±4000 °/s), so a
# rad/s recording whose 99th percentile of |gyr| exceeds 2000 °/s ≈ 34.9 rad/s would have at least 1 % of
# its samples beyond the range of nearly every gyro (a saturating ±2000 °/s gyro clips at 34.9). Everyday
# human and robot motion stays well below (fast BROAD trials: 99th percentile 11–19 rad/s); faster motion
# saturates the gyro rather than exceeding it. The same numbers in deg/s (35–2000 °/s) are ordinary. The
# percentile ignores up to 1 % of glitches. Not detectable by magnitude: deg/s data whose motion stays
# below 35 °/s, and rad/s data read as deg/s (57× too small looks like slow motion); the tilt check below is.
GYR_MAX_RAD_S = 35.0
GYR_PERCENTILE = 99.0

# Gyro against accelerometer (riann_ros.datasets.gyro_tilt): per tilt of the gravity direction, how many times as far
# the gyro turns it. The unit whose factor is nearest is judged when at least TILT_MIN_COUNT tilts were measured and
# at least TILT_MAJORITY of them lie within a factor TILT_RATIO_TOL of it. 3 is below √17.5 ≈ 4.2, half the
# log-distance of the closest pair of unit factors (deg/s and mrad/s, 17.5× apart), so each tilt counts for one unit
# at most, and wide enough for the ±50 % that bias and linear acceleration may move one tilt's ratio. Fewer tilts, or
# no majority (apparent tilts made by linear acceleration, a gyro whose axes do not match the accelerometer's): no
# judgement.
TILT_MIN_COUNT = 5
TILT_RATIO_TOL = 3.0
TILT_MAJORITY = 0.5

# Magnetic field. Earth's field is 25–65 µT at the surface (WMM); an uncalibrated magnetometer adds a
# hard-iron offset of tens of µT, up to ~100 µT beside motors or steel, and indoor fields vary by tens of
# µT. 10–200 µT keeps all of that and rejects every unit mix-up, each a factor of 100 or more: gauss
# (1 G = 100 µT), mT (1000 µT), nT (1/1000 µT), T read as µT (10⁶). The median over the finite samples
# ignores short disturbances.
MAG_MIN_T = 10e-6
MAG_MAX_T = 200e-6

# Canonical units (aliases such as "µs", "dps", "m/s^2" map onto these) and their scale to ns, m/s², rad/s.
TIME_SCALES: dict[str, float] = {"s": 1e9, "ms": 1e6, "us": 1e3, "ns": 1.0}
ACC_SCALES: dict[str, float] = {"m/s2": 1.0, "g": GRAVITY}
GYR_SCALES: dict[str, float] = {"rad/s": 1.0, "deg/s": DEG, "mrad/s": 1e-3, "mdeg/s": 1e-3 * DEG}
MAG_SCALES: dict[str, float] = {"T": 1.0, "mT": 1e-3, "G": 1e-4, "uT": 1e-6, "nT": 1e-9}
_ALIASES = {"µs": "us", "m/s^2": "m/s2", "m/s²": "m/s2", "dps": "deg/s", "mdps": "mdeg/s", "µT": "uT", "gauss": "G",
            "tesla": "T"}


@dataclass(frozen=True)
class Finding:
    """One implausible quantity.

    ``check``: ``"rate"``, ``"acc"``, ``"gyr"`` or ``"mag"``; ``option``: the reader option that sets the
    unit (``time_unit``, ``acc_unit``, ``gyr_unit``, ``mag_unit``); ``value``: the measured value in Hz,
    m/s², rad/s or T (as read); ``unit``: the unit the values were read in; ``suggest``: the unit that
    makes it plausible, or None when none does; ``message``: what was measured and what it looks like.
    """

    check: str
    option: str
    value: float
    unit: str
    suggest: str | None
    message: str

    @property
    def flag(self) -> str:
        """The converter option that sets this unit: ``--time-unit``, ``--acc-unit``, ``--gyr-unit``, ``--mag-unit``."""
        return "--" + self.option.replace("_", "-")

    def __str__(self) -> str:
        return self.message


def canonical_unit(unit: str, scales: Mapping[str, float]) -> str:
    """``unit`` or its canonical spelling in ``scales`` (``"µs"`` → ``"us"``); ValueError if unknown."""
    u = _ALIASES.get(unit, unit)
    if u not in scales:
        raise ValueError(f"unknown unit {unit!r}; expected one of {', '.join(scales)}")
    return u


def _candidates(value: float, unit: str, scales: Mapping[str, float], ok) -> list[tuple[str, float]]:
    """(unit, value if the raw numbers were in that unit) for the other units in which ``ok(value)`` holds.

    ``value`` is in the base unit (ns-based rate, m/s², rad/s) after reading the raw numbers as ``unit``;
    reading them as ``u`` instead multiplies it by ``scales[u] / scales[unit]``.
    """
    out = []
    for u, s in scales.items():
        if u != unit:
            v = value * s / scales[unit]
            if ok(v):
                out.append((u, v))
    return out


def _scale_finding(check: str, value: float, unit: str, scales: Mapping[str, float], plausible: tuple[float, float],
                   text: str) -> Finding | None:
    """None for a ``value`` (read as ``unit``) within the ``plausible`` range; else its Finding: the first other unit
    of ``scales`` in which it would be plausible is suggested, or none."""
    lo, hi = plausible
    if lo <= value <= hi:
        return None
    option = f"{check}_unit"
    cands = _candidates(value, unit, scales, lambda v: lo <= v <= hi)
    if not cands:
        return Finding(check, option, value, unit, None, f"{text}: implausible in any unit ({', '.join(scales)})")
    best = cands[0][0]
    return Finding(check, option, value, unit, best, f"{text}: looks like {best} read as {unit}")


def _fmt_duration(seconds: float) -> str:
    for unit, scale in (("s", 1.0), ("ms", 1e-3), ("µs", 1e-6)):
        if abs(seconds) >= scale:
            return f"{seconds / scale:.4g} {unit}"
    return f"{seconds * NS_PER_S:.4g} ns"


def check_rate(rec: Recording, time_unit: str = "s") -> Finding | None:
    """Sample rate (1 / median stamp step) within [RATE_MIN_HZ, RATE_MAX_HZ], else a Finding."""
    if len(rec) < 2:
        return None
    unit = canonical_unit(time_unit, TIME_SCALES)
    step_s = float(np.median(np.diff(rec.stamps_ns))) * 1e-9
    rate = 1.0 / step_s
    if RATE_MIN_HZ <= rate <= RATE_MAX_HZ:
        return None
    # the step is (raw step) × scale[unit]; in unit u it would be (raw step) × scale[u]: rate × scale[unit]/scale[u]
    inv = {u: 1.0 / s for u, s in TIME_SCALES.items()}
    cands = _candidates(rate, unit, inv, lambda r: RATE_MIN_HZ <= r <= RATE_MAX_HZ)
    text = (
        f"median time step {_fmt_duration(step_s)} ({rate:.4g} Hz) is outside the plausible IMU rate "
        f"{RATE_MIN_HZ:g} Hz – {RATE_MAX_HZ / 1000:g} kHz"
    )
    if not cands:
        return Finding(
            "rate",
            "time_unit",
            rate,
            unit,
            None,
            f"{text}; no time unit ({', '.join(TIME_SCALES)}) gives a plausible rate",
        )
    best, r = min(cands, key=lambda c: abs(math.log(c[1] / TYPICAL_RATE_HZ)))
    return Finding(
        "rate", "time_unit", rate, unit, best, f"{text}: looks like {best} stamps read as {unit} ({r:.4g} Hz)"
    )


def rest_mask(gyr: np.ndarray) -> np.ndarray:
    """Samples at rest: |gyr| < REST_GYR_RAD_S (rad/s)."""
    return np.asarray(np.linalg.norm(gyr, axis=1) < REST_GYR_RAD_S)


def check_gravity(rec: Recording, acc_unit: str = "m/s2", gyr_scale: float = 1.0) -> Finding | None:
    """Median |acc| at rest within [ACC_REST_MIN, ACC_REST_MAX] m/s², else a Finding.

    Rest = |gyr · gyr_scale| < REST_GYR_RAD_S (``gyr_scale`` corrects a gyro unit already found wrong);
    with fewer than REST_MIN_SAMPLES rest samples the median is over all samples.
    """
    if len(rec) == 0:
        return None
    unit = canonical_unit(acc_unit, ACC_SCALES)
    norm = np.linalg.norm(rec.acc, axis=1)
    rest = rest_mask(rec.gyr * gyr_scale)
    n_rest = int(rest.sum())
    over = f"{n_rest} samples at rest (|gyr| < {REST_GYR_RAD_S:g} rad/s)"
    if n_rest < REST_MIN_SAMPLES:
        rest[:] = True
        over = f"all {len(rec)} samples (none at rest)"
    value = float(np.median(norm[rest]))
    text = (
        f"median |acc| {value:.4g} m/s² over {over}, expected gravity ≈ {GRAVITY:.2f} "
        f"({ACC_REST_MIN:g}–{ACC_REST_MAX:g})"
    )
    return _scale_finding("acc", value, unit, ACC_SCALES, (ACC_REST_MIN, ACC_REST_MAX), text)


def check_gyro(rec: Recording, gyr_unit: str = "rad/s") -> Finding | None:
    """GYR_PERCENTILE of |gyr| at most GYR_MAX_RAD_S rad/s, else a Finding."""
    if len(rec) == 0:
        return None
    unit = canonical_unit(gyr_unit, GYR_SCALES)
    value = float(np.percentile(np.linalg.norm(rec.gyr, axis=1), GYR_PERCENTILE))
    text = (
        f"{GYR_PERCENTILE:g}th percentile of |gyr| {value:.4g} rad/s is above {GYR_MAX_RAD_S:g} rad/s "
        f"(2000 °/s, the full scale of common MEMS gyros)"
    )
    return _scale_finding("gyr", value, unit, GYR_SCALES, (-math.inf, GYR_MAX_RAD_S), text)


def check_gyro_tilt(rec: Recording, gyr_unit: str = "rad/s", time_scale: float = 1.0) -> Finding | None:
    """The gyro against the accelerometer: a Finding when the gyro turns the gravity direction by a unit factor
    other than 1 (:mod:`riann_ros.datasets.gyro_tilt`), None when it fits or the recording cannot show it.
    ``time_scale`` corrects stamps whose unit was already found wrong (the gyro is integrated over time)."""
    unit = canonical_unit(gyr_unit, GYR_SCALES)
    stamps = rec.stamps_ns if time_scale == 1.0 else np.round(rec.stamps_ns * time_scale).astype(np.int64)
    tilts = measure_tilts(stamps, rec.acc, rec.gyr)
    if len(tilts) < TILT_MIN_COUNT:
        return None
    log_r = np.log(tilts.ratio)
    # reading numbers of unit u as `unit` makes the gyro GYR_SCALES[unit] / GYR_SCALES[u] times too large
    expected = {u: GYR_SCALES[unit] / s for u, s in GYR_SCALES.items()}
    # A gyro too small for the tilts might only show bias beside tilts made by linear acceleration: such a unit is
    # taken only where the gyro, while still, would read a plausible bias in it (BIAS_MAX_DEG_S).
    expected = {u: r for u, r in expected.items() if r >= 1.0 or tilts.still_rate / r <= BIAS_MAX_DEG_S * DEG}
    votes = {u: int((np.abs(log_r - math.log(r)) < math.log(TILT_RATIO_TOL)).sum()) for u, r in expected.items()}
    best = max(votes, key=lambda u: votes[u])
    if best == unit or votes[best] < max(TILT_MIN_COUNT, TILT_MAJORITY * len(tilts)):
        return None
    ratio = float(np.exp(np.median(log_r)))
    text = (f"the gyro, read as {unit}, turns the gravity direction {ratio:.3g} times as far as the accelerometer "
            f"shows it turn (median of {len(tilts)} tilts of {np.median(tilts.tilt_deg):.0f}°, {votes[best]} "
            f"fitting {best}): looks like {best} read as {unit}")
    return Finding("gyr", "gyr_unit", ratio, unit, best, text)


def check_mag(rec: Recording, mag_unit: str = "T") -> Finding | None:
    """Median |field| over the finite magnetometer samples within [MAG_MIN_T, MAG_MAX_T], else a Finding
    (None without a magnetometer)."""
    if rec.mag is None:
        return None
    norm = np.linalg.norm(rec.mag, axis=1)
    norm = norm[np.isfinite(norm)]
    if len(norm) == 0:
        return None
    unit = canonical_unit(mag_unit, MAG_SCALES)
    value = float(np.median(norm))
    text = (
        f"median |mag| {value * 1e6:.4g} µT, expected Earth's field 25–65 µT "
        f"({MAG_MIN_T * 1e6:g}–{MAG_MAX_T * 1e6:g} with calibration offsets)"
    )
    return _scale_finding("mag", value, unit, MAG_SCALES, (MAG_MIN_T, MAG_MAX_T), text)


def check_units(
    rec: Recording, *, time_unit: str | None = None, acc_unit: str | None = None, gyr_unit: str | None = None
) -> list[Finding]:
    """The implausible rate, gravity, gyro range and magnetic field findings of ``rec`` (empty: all plausible).

    The units are those the raw numbers were read in (they decide which other unit is suggested); by
    default ``rec.meta["time_unit"]`` etc. when present (the CSV reader records them), else s, m/s², rad/s.
    """
    time_unit = time_unit or rec.meta.get("time_unit", "s")
    acc_unit = acc_unit or rec.meta.get("acc_unit", "m/s2")
    gyr_unit = gyr_unit or rec.meta.get("gyr_unit", "rad/s")
    rate = check_rate(rec, time_unit)
    findings = [rate]
    gyr = check_gyro(rec, gyr_unit)
    tilt = None
    if rate is None or rate.suggest is not None:  # the gyro is integrated over time: in the time unit that fits
        time_scale = 1.0 if rate is None else TIME_SCALES[rate.suggest] / TIME_SCALES[rate.unit]  # type: ignore[index]
        tilt = check_gyro_tilt(rec, gyr_unit, time_scale)
    if tilt is not None and (gyr is None or tilt.suggest != gyr.suggest):
        gyr = tilt  # the tilt check measures the factor; the range check only bounds it
    gyr_scale = 1.0
    if gyr is not None and gyr.suggest is not None:  # find rest with the gyro in the suggested unit
        gyr_scale = GYR_SCALES[gyr.suggest] / GYR_SCALES[gyr.unit]
    findings += [check_gravity(rec, acc_unit, gyr_scale), gyr, check_mag(rec, rec.meta.get("mag_unit", "T"))]
    return [f for f in findings if f is not None]
