"""What crosses the calibration's boundary: the prior it starts from, the estimate it hands out, its state, and the
physical constants it is built on (ROS-free, frozen records).

Conventions (the node's, :mod:`riann_ros.magcal.input`): the calibrated field is ``m = S (m_raw − h)`` with the
hard-iron offset ``h`` in tesla (sensor frame) and the soft-iron matrix ``S`` row-major 3×3. Covariances are over
the 12 numbers ``(S row-major (9), h in T (3))`` in that order, row-major 12×12.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from riann_ros.constants import DEG

UT = 1e-6  # T per µT: the calibration computes in µT (Earth's field ≈ 25–65 µT: numbers of order one)
USABLE_MIN_T = 1e-6  # T; a reading below: a dead sensor or a field in the wrong unit (not used)
USABLE_MAX_T = 1e-3  # T; a reading above: saturated, or a magnet next to the sensor (not used)
IDENTITY_9 = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)

# ------------------------------------------------------------------------------------------------------------------
# The noise of one window's constraint (docs in riann_ros/magcal/__init__.py): chosen from sensor physics and data
# sheets, never fitted to recordings. The residual scale is checked online (the variance of unit weight,
# :class:`~riann_ros.magcal.online.OnlineMagCalibrator`), so a sensor noisier than these figures widens the σ.
# ------------------------------------------------------------------------------------------------------------------
#: µT; white noise of one magnetometer reading: MEMS magnetometers' data sheets give 0.1–0.6 µT rms at 100–1000 Hz
#: (e.g. LIS3MDL 0.32 µT, BMM150 0.3–0.6 µT, AK09916 0.15 µT/LSB); the upper end of the range.
MAG_NOISE_SD_UT = 0.5
#: µT; how much the world field differs between a window's two readings however short it is (the readings'
#: positions differ by the sensor's lever arm; indoors steel makes the field vary by about a µT per metre).
FIELD_CHANGE_SD_UT = 0.5
#: µT/s; how fast the world field seen by a moving sensor changes: about a µT per metre indoors, at up to a metre per
#: second of travel. A long window of slow rotation during fast translation weighs little.
FIELD_CHANGE_RATE_UT_S = 1.0
#: µT; the hard iron is never known better than this per axis, however many windows: the world field's
#: non-uniformity over the space the sensor moves in (a µT per metre over half a metre) biases every window alike,
#: so it does not average out. The reported covariance's floor (not the estimate's).
SYSTEMATIC_SD_UT = 0.5
#: µT; per axis, how far a hard iron moves between two runs of one sensor (temperature, the magnetisation the sensor's
#: and the robot's steel take between power-ups, a cable rerouted): a saved calibration is the prior of a later run
#: with this much more doubt on its hard iron than its own fit had. Measured on the BROAD trials of one sensor
#: (``bench/mag_run_to_run.py``: the offline fit of each trial whose motion observes the hard iron, the RMS of its
#: difference between every two trials, per axis, pooled: 1.2 µT; the fits' own σ is 0.55 µT).
RUN_TO_RUN_HARD_IRON_SD_UT = 1.2
#: rad/s; the gyro bias left after the bias front end (VQF's rest and motion estimate, RIANN's stage 3): a few
#: tenths of °/s while it converges.
GYRO_BIAS_RESIDUAL_SD_RAD_S = 0.3 * DEG
#: the gyro's scale-factor error: consumer MEMS sensitivity tolerance ±1–3 % untrimmed, ≤ 1 % trimmed.
GYRO_SCALE_SD = 0.01
#: s; the uncertainty of the magnetometer's latency against the gyro after compensation (the front end's latency fit
#: estimates it to a few ms; a sample's rounding adds up to half a step).
DELAY_SD_S = 0.003
#: s; the latency compensation keeps the gyro attitude of the last this many seconds (the latency fit's bound:
#: 0–100 ms).
MAX_DELAY_S = 0.1

# ------------------------------------------------------------------------------------------------------------------
# Windows (riann_ros/magcal/windows.py)
# ------------------------------------------------------------------------------------------------------------------
#: rad; a window closes once the sensor has turned this far: the constraint's signal is 2 sin(θ/2)|B| (0.77|B| at
#: 45°, 35 µT at Earth's 45 µT against a noise of ~1.5 µT), and the information per degree turned,
#: ∝ sin²(θ/2)/θ, is within 20 % of its best (θ ≈ 133°) while the gyro's scale error (1 % of θ) stays small.
WINDOW_ANGLE_RAD = 45.0 * DEG
#: s; a window that has not turned WINDOW_ANGLE_RAD in this time closes if it turned at least WINDOW_MIN_ANGLE_RAD,
#: else it is dropped: the gyro bias residual (0.3 °/s × 5 s = 1.5°, 1.2 µT at 45 µT) then equals the field noise.
WINDOW_MAX_S = 5.0
#: rad; the least rotation a window must have: below it the signal (< 0.26|B| = 12 µT) is too weak against the
#: noise, and a window of noise alone would pull the soft-iron matrix toward zero (errors in the variables).
WINDOW_MIN_ANGLE_RAD = 15.0 * DEG
#: s; a step longer than this breaks the window (the gyro's rotation across a hole is not known well enough).
MAX_STEP_S = 0.2

# ------------------------------------------------------------------------------------------------------------------
# Prior, gate, state
# ------------------------------------------------------------------------------------------------------------------
#: T; the prior standard deviation of an unknown hard iron per axis: a robot's motors, battery, frame and board
#: add "tens of µT" (Earth's field ≈ 50 µT).
HARD_IRON_PRIOR_SD_T = 50e-6  # (50 µT written in T: the exact float of config/riann.yaml's 5.0e-05)
#: the prior standard deviation of the soft iron's symmetric part per entry (Frobenius-isotropic): soft-iron scale
#: errors and cross-coupling of 5–15 %.
SOFT_IRON_PRIOR_SD = 0.1
#: rad; the prior standard deviation of the soft iron's antisymmetric part (a small rotation: the magnetometer's
#: misalignment to the gyro, about each axis): a magnetometer on the IMU's board or in its package is aligned to
#: about a degree. Only the full soft-iron model estimates it; a rotation about the only axis a ground robot turns
#: about is unobservable (a heading offset), so this prior is what bounds it there.
MISALIGNMENT_PRIOR_SD_RAD = 1.0 * DEG
#: a window whose innovation's Mahalanobis distance² exceeds this is rejected as a magnetic disturbance: the 99.9 %
#: quantile of χ² with 3 degrees of freedom (a consistent window is rejected once in 1000).
GATE_CHI2 = 16.27
#: consecutive rejected windows that agree with one another replace the estimate: the magnetic situation has changed
#: (a payload or magnet added or removed, or the first windows were disturbed). A consistent estimate is rejected 20
#: times in a row with probability 1e-60 at GATE_CHI2, and 20 windows of 45° determine the new one to about a µT.
SWITCH_WINDOWS = 20
#: windows' worth of weight of the prior value 1 in the running variance of unit weight (keeps the first few
#: windows' scale from swinging the σ).
UNIT_WEIGHT_PRIOR_WINDOWS = 10.0
#: rad; the field heading's own σ (RIANN's stage 8: 2.5°, fitted on BROAD's calibrated field, so it already holds a
#: calibrated magnetometer's residual error). The calibration is *calibrated* once the heading error it can add at
#: the current tilt is no larger: the heading's σ is then within √2 of a calibrated sensor's. (Its floor,
#: SYSTEMATIC_SD_UT over the horizontal field, is 1.4° at 20 µT, 1.8° at BROAD's 16 µT: reachable where the
#: horizontal field is above ~11.5 µT.)
FIELD_HEADING_SD_RAD = 2.5 * DEG
CALIBRATED_SD_RAD = FIELD_HEADING_SD_RAD
#: the per-sample heading σ refreshes its cached field covariance each time the sensor has turned this far.
REFRESH_ANGLE_RAD = 15.0 * DEG
#: headings sampled around the current tilt for the state's bound (every 15°).
STATE_HEADINGS = 24

SoftIronModel = Literal["none", "symmetric", "full"]
SOFT_IRON_MODELS: tuple[str, ...] = ("none", "symmetric", "full")
CalState = Literal["uncalibrated", "converging", "calibrated"]
UNCALIBRATED: CalState = "uncalibrated"
CONVERGING: CalState = "converging"
CALIBRATED: CalState = "calibrated"
STATES: tuple[str, ...] = (UNCALIBRATED, CONVERGING, CALIBRATED)


def _finite(values: tuple[float, ...], what: str, n: int) -> tuple[float, ...]:
    out = tuple(float(v) for v in values)
    if len(out) != n or not all(math.isfinite(v) for v in out):
        raise ValueError(f"{what}: expected {n} finite numbers, got {values!r}")
    return out


@dataclass(frozen=True)
class MagCalPrior:
    """Where a calibration starts: the configured (or saved) ``h`` and ``S`` and how well they are known, either
    as standard deviations (``hard_iron_sd_t`` per axis, ``soft_iron_sd`` per entry of the symmetric part,
    ``misalignment_sd_rad`` per axis of the antisymmetric part) or, from a saved calibration,
    as the full covariance (12×12 over ``(S, h)``, see the module docstring; it then replaces the two σ)."""

    hard_iron_t: tuple[float, float, float] = (0.0, 0.0, 0.0)
    soft_iron: tuple[float, ...] = IDENTITY_9
    hard_iron_sd_t: float = HARD_IRON_PRIOR_SD_T
    soft_iron_sd: float = SOFT_IRON_PRIOR_SD
    misalignment_sd_rad: float = MISALIGNMENT_PRIOR_SD_RAD
    covariance: tuple[float, ...] | None = None
    windows: int = 0  # windows already in the covariance (a saved calibration's)
    converged_after_s: float | None = None  # a saved calibration's

    def __post_init__(self) -> None:
        object.__setattr__(self, "hard_iron_t", _finite(self.hard_iron_t, "hard_iron_t", 3))
        object.__setattr__(self, "soft_iron", _finite(self.soft_iron, "soft_iron", 9))
        if not (self.hard_iron_sd_t > 0.0 and self.soft_iron_sd > 0.0 and self.misalignment_sd_rad > 0.0):
            raise ValueError("prior standard deviations must be positive")
        if self.covariance is not None:
            object.__setattr__(self, "covariance", _finite(self.covariance, "covariance", 144))

    @classmethod
    def from_calibration(cls, cal: MagCalibration) -> MagCalPrior:
        """A saved calibration as the prior of the next run (it starts where that one ended): its covariance, with
        the hard iron's variance widened by how much a hard iron moves between runs
        (:data:`RUN_TO_RUN_HARD_IRON_SD_UT` per axis, the file's fit knows only its own run)."""
        cov = list(cal.covariance)
        for i in range(9, 12):
            cov[i * 12 + i] += (RUN_TO_RUN_HARD_IRON_SD_UT * UT) ** 2
        return cls(hard_iron_t=cal.hard_iron_t, soft_iron=cal.soft_iron, covariance=tuple(cov),
                   windows=cal.windows, converged_after_s=cal.converged_after_s)


@dataclass(frozen=True)
class MagCalibration:
    """A calibration estimate: ``h`` (T), ``S`` (row-major), their covariance (12×12 row-major over
    ``(S, h)``), the state, how many windows it holds, when it was first called calibrated (s after its run's first
    sample, None: not yet) and the soft-iron model it was estimated with."""

    hard_iron_t: tuple[float, float, float]
    soft_iron: tuple[float, ...]
    covariance: tuple[float, ...]
    state: CalState
    windows: int
    converged_after_s: float | None
    soft_iron_model: SoftIronModel

    def __post_init__(self) -> None:
        object.__setattr__(self, "hard_iron_t", _finite(self.hard_iron_t, "hard_iron_t", 3))
        object.__setattr__(self, "soft_iron", _finite(self.soft_iron, "soft_iron", 9))
        object.__setattr__(self, "covariance", _finite(self.covariance, "covariance", 144))
        if self.state not in STATES:
            raise ValueError(f"state must be one of {', '.join(STATES)}, got {self.state!r}")
        if self.soft_iron_model not in SOFT_IRON_MODELS:
            raise ValueError(f"soft_iron_model must be one of {', '.join(SOFT_IRON_MODELS)}")

    @property
    def hard_iron_sd_t(self) -> tuple[float, float, float]:
        """T; the hard iron's standard deviation per axis."""
        c = self.covariance
        return (math.sqrt(max(c[9 * 12 + 9], 0.0)), math.sqrt(max(c[10 * 12 + 10], 0.0)),
                math.sqrt(max(c[11 * 12 + 11], 0.0)))


@dataclass(frozen=True)
class MagCalStatus:
    """What the node's ``/diagnostics`` shows, once per window: the state, the estimate and its uncertainty, the
    bound of the heading error it can add at the current tilt (rad), the windows used and rejected as disturbed,
    the residual scale (the variance of unit weight; ≈ 1 when the noise model fits), and whether the configured
    (or saved) calibration is in use (:mod:`~riann_ros.magcal.hypothesis`: it holds, as the more probable
    hypothesis)."""

    state: CalState
    hard_iron_t: tuple[float, float, float]
    hard_iron_sd_t: tuple[float, float, float]
    heading_sd_bound_rad: float
    windows: int
    rejected: int
    unit_weight: float
    converged_after_s: float | None
    prior_holds: bool = True
