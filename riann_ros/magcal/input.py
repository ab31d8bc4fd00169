"""The magnetometer input: pairing with IMU samples, calibration, plausibility and ``use_mag`` (ROS-free).

Shared by the node base (which receives ``sensor_msgs/MagneticField`` on its own topic) and the offline
path (bag reader, evaluator), so both give an estimator the same field for the same IMU sample:

* **pairing** (:class:`MagPairing` per message, :func:`pair_fields` for whole arrays): an IMU sample gets
  the newest field reading stamped at or before its own stamp, if that reading is at most
  ``mag_timeout`` older; otherwise none. Never waits for a reading: a slower or late magnetometer
  only means samples without a field.
* **calibration** (:class:`MagInput`): ``m = S (m_raw − h)`` with the hard-iron offset ``h`` (tesla,
  sensor frame) and the soft-iron matrix ``S`` (row-major 3×3), as calibration tools report them. With an
  estimator that calibrates online (its ``mag_calibration`` parameter, :data:`MAG_CAL_PARAMS`) the raw field
  passes instead (:attr:`MagInput.raw`) and ``h``, ``S`` are where its calibration starts (:meth:`MagConfig.prior`).
* **plausibility**: a reading that is not finite, zero, or whose norm is outside
  [:data:`USABLE_MIN_T`, :data:`USABLE_MAX_T`] (a dead or saturated sensor; Earth's field is 25–65 µT) is not
  used; the estimator then runs 6D for that sample (its heading follows the gyro).
* ``use_mag``: ``auto`` (default) uses the field whenever a fresh, plausible one is paired; ``true``
  does the same and reports a missing field as a warning; ``false`` never passes a field.
* **declination_deg** (east positive): 9D estimators reference their heading to magnetic north; once a
  field has been used the output is rotated by ``Rz(−declination_deg)`` so that the ENU y axis is true north.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum
from typing import TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from riann_ros.magcal.records import IDENTITY_9, SOFT_IRON_MODELS, USABLE_MAX_T, USABLE_MIN_T, MagCalPrior
from riann_ros.params import ParamSpec, defaults

F = TypeVar("F", float, NDArray[np.float64])  # one field's component (float) or a column of fields (array)



class UseMag(Enum):
    """The ``use_mag`` parameter: what the stream does with a paired field (module docstring)."""

    AUTO = "auto"  # use the field whenever a fresh, plausible one is paired
    TRUE = "true"  # the same, and a missing field is a warning
    FALSE = "false"  # never pass a field

    @classmethod
    def parse(cls, value: object) -> UseMag:
        """The setting from what a user writes: ``auto``, ``true``/``false`` in any case, a bool, or a member."""
        if isinstance(value, UseMag):
            return value
        if isinstance(value, bool):
            return cls.TRUE if value else cls.FALSE
        try:
            return cls(str(value).strip().lower())
        except ValueError:
            raise ValueError(f"use_mag must be one of {', '.join(USE_MAG_CHOICES)}, got {value!r}") from None


USE_MAG_CHOICES = tuple(m.value for m in UseMag)

# state of the field for the last sample (diagnostics)
FIELD_USED = "9D: field used"
FIELD_OFF = "6D: use_mag is false"
FIELD_NONE = "6D: no field received"
FIELD_STALE = "6D: no fresh field"
FIELD_BAD = "6D: implausible field"
FIELD_NONFINITE = "6D: field readings not finite"

MAG_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec("use_mag", "auto", "Magnetometer on imu/mag: auto = use it while fresh field samples arrive (9D), "
              "gyro-held heading otherwise (6D); true = the same, a missing field is a warning; false = ignore it.",
              choices=USE_MAG_CHOICES),
    ParamSpec("mag_timeout", 0.5, "s; a field reading older than this (relative to the IMU stamp) is stale: "
              "the sample is processed without a field.", min=0.001, max=60.0, runtime=True),
    ParamSpec("mag_hard_iron", (0.0, 0.0, 0.0), "T; hard-iron offset subtracted from the field (sensor frame).",
              min=-1.0, max=1.0, runtime=True),
    ParamSpec("mag_soft_iron", IDENTITY_9, "Soft-iron matrix S (row-major 3x3) applied after the offset: "
              "m = S (m_raw - hard_iron).", min=-1.0e3, max=1.0e3, runtime=True),
    ParamSpec("declination_deg", 0.0, "deg, east positive; magnetic declination at the site, so that the heading "
              "of a 9D estimate is relative to true north.", min=-180.0, max=180.0, runtime=True),
)
_MAG_DEFAULTS = defaults(MAG_PARAMS)

#: The online calibration's parameters (:mod:`riann_ros.magcal`), part of every 9D estimator's parameters (they
#: decide what the estimator does with the field); its prior is :data:`MAG_PARAMS`' ``mag_hard_iron`` and
#: ``mag_soft_iron`` (:meth:`MagConfig.prior`) or a saved calibration. docs/magnetometer.md.
MAG_CAL_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec("mag_calibration", True, "Calibrate the magnetometer online (hard iron, and soft iron where the motion "
              "observes it; gyro-aided): mag_hard_iron and mag_soft_iron are the hypothesis it starts from, used as "
              "they are while the gyro-aided test finds the field consistent with them; once it does not, the "
              "heading trusts the field only as far as the calibration knows it. false = the field is calibrated "
              "with mag_hard_iron and mag_soft_iron only."),
    ParamSpec("mag_hard_iron_sd", 5e-5, "T; per axis, how far the hard iron may be from mag_hard_iron "
              "once the data rejects it (the calibration's prior standard deviation; a robot's motors, battery and "
              "frame add tens of µT).", min=1e-9, max=1e-3),
    ParamSpec("mag_soft_iron_model", "full", "Soft iron the online calibration estimates: full (3x3, with the "
              "magnetometer's misalignment to the gyro), symmetric, none (hard iron only).", choices=SOFT_IRON_MODELS),
)


@dataclass
class MagConfig:
    """The magnetometer parameters (see :data:`MAG_PARAMS`); ``use_mag`` is parsed into :class:`UseMag`."""

    use_mag: UseMag = UseMag.AUTO
    mag_timeout: float = _MAG_DEFAULTS["mag_timeout"]
    mag_hard_iron: tuple[float, ...] = _MAG_DEFAULTS["mag_hard_iron"]
    mag_soft_iron: tuple[float, ...] = _MAG_DEFAULTS["mag_soft_iron"]
    declination_deg: float = _MAG_DEFAULTS["declination_deg"]

    def __post_init__(self) -> None:
        for spec in MAG_PARAMS:
            value = getattr(self, spec.name)
            if spec.name == "use_mag":
                setattr(self, spec.name, UseMag.parse(value))
            else:
                setattr(self, spec.name, spec.validate(value))

    @property
    def timeout_ns(self) -> int:
        return round(self.mag_timeout * 1e9)

    def prior(self) -> MagCalPrior:
        """The configured calibration as the online calibration's starting point (its σ: the estimator's)."""
        return MagCalPrior(hard_iron_t=self.mag_hard_iron, soft_iron=self.mag_soft_iron)  # type: ignore[arg-type]


class MagPairing:
    """Field readings as they arrive (node side); :meth:`at` pairs one with an IMU stamp. It counts what the
    magnetometer's field monitor reports: readings received, readings stamped before the previous one (the pairing
    starts over), and IMU samples whose newest reading was older than the timeout (stale)."""

    KEEP = 100_000  # at most this many readings ahead of the IMU are kept (a stalled IMU stream)

    def __init__(self) -> None:
        self._readings: deque[tuple[int, tuple[float, float, float]]] = deque(maxlen=self.KEEP)
        self.received = 0
        self.out_of_order = 0
        self.stale = 0

    def clear(self) -> None:
        self._readings.clear()

    def push(self, stamp_ns: int, field: ArrayLike) -> None:
        """A reading as it arrives (any time before or after the IMU samples it belongs to)."""
        x, y, z = (float(v) for v in np.asarray(field, dtype=float).reshape(3))
        if self._readings and stamp_ns < self._readings[-1][0]:
            self._readings.clear()  # the magnetometer's clock went back: start over
            self.out_of_order += 1
        self._readings.append((int(stamp_ns), (x, y, z)))
        self.received += 1

    def at(self, stamp_ns: int, timeout_ns: int) -> tuple[tuple[float, float, float] | None, int | None]:
        """(the newest reading at or before ``stamp_ns`` not older than ``timeout_ns`` or None, its age in ns or
        None when no reading at or before the stamp exists)."""
        r = self._readings
        # IMU stamps increase: readings older than the newest one at or before this stamp are never needed again
        while len(r) > 1 and r[1][0] <= stamp_ns:
            r.popleft()
        if r and r[0][0] <= stamp_ns:
            t, v = r[0]
            age = stamp_ns - t
            if age <= timeout_ns:
                return v, age
            self.stale += 1
            return None, age
        return None, None


def pair_fields(imu_stamps: ArrayLike, mag_stamps: ArrayLike, mag: ArrayLike, timeout_ns: int) -> NDArray[np.float64]:
    """:class:`MagPairing` over whole arrays: (N, 3) fields for the IMU stamps, NaN rows where none is fresh.
    ``mag_stamps`` must be sorted."""
    ts = np.asarray(imu_stamps, dtype=np.int64)
    ms = np.asarray(mag_stamps, dtype=np.int64)
    vals = np.asarray(mag, dtype=float).reshape(-1, 3)
    out = np.full((len(ts), 3), np.nan)
    if len(ms) == 0:
        return out
    k = np.searchsorted(ms, ts, side="right") - 1
    ok = k >= 0
    ok[ok] = (ts[ok] - ms[k[ok]]) <= timeout_ns
    out[ok] = vals[k[ok]]
    return out


def plausible(field: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Rows (N, 3) that are finite with a norm within [USABLE_MIN_T, USABLE_MAX_T]."""
    with np.errstate(invalid="ignore", over="ignore"):
        n = np.linalg.norm(field, axis=-1)
    return np.isfinite(n) & (n >= USABLE_MIN_T) & (n <= USABLE_MAX_T)


def _floats(v: ArrayLike) -> tuple[float, float, float]:
    """Three floats of a field given as a tuple or list (a message's fields, the pairing's) or an array."""
    x, y, z = v if isinstance(v, (tuple, list)) else np.asarray(v, dtype=float).reshape(3).tolist()
    return float(x), float(y), float(z)


def rot_z(angle_rad: float) -> NDArray[np.float64]:
    return np.array([math.cos(0.5 * angle_rad), 0.0, 0.0, math.sin(0.5 * angle_rad)])


def calibrated(h: Sequence[float], s: Sequence[float], x: F, y: F, z: F) -> tuple[F, F, F]:
    """``S (m − h)``: a field (floats, or columns of fields as arrays) through the hard iron ``h`` and the row-major
    soft iron ``s`` of a calibration, as the parameters ``mag_hard_iron`` and ``mag_soft_iron`` mean them."""
    dx, dy, dz = x - h[0], y - h[1], z - h[2]
    return (s[0] * dx + s[1] * dy + s[2] * dz, s[3] * dx + s[4] * dy + s[5] * dz,
            s[6] * dx + s[7] * dy + s[8] * dz)


class MagInput:
    """What the stream does with the paired field before and after the estimator (see the module docstring).

    :meth:`prepare` / :meth:`prepare_batch` give the calibrated field for the estimator (or none) and record
    why not; :meth:`note` / :meth:`used` track whether a field has been used since the last reset, and
    :meth:`declination_applied` rotates the outputs from then on.
    """

    def __init__(self, config: MagConfig | None = None, raw: bool = False) -> None:
        self.config = config or MagConfig()
        self.raw = raw  # pass the raw field: the estimator calibrates it (plausibility is tested on the raw field)
        self.samples_with_field = 0  # samples that went to the estimator with a field (never reset)
        #: paired readings that were not finite, and that were outside the plausible norms (never reset)
        self.non_finite = 0
        self.implausible = 0
        self.reset()

    def reset(self) -> None:
        self.seen = False  # a field was passed to the estimator since the last reset
        self.state = FIELD_OFF if self.config.use_mag is UseMag.FALSE else FIELD_NONE

    def _calibrated(self, x: F, y: F, z: F) -> tuple[F, F, F]:
        """``S (m − h)`` of one field (floats) or of columns of fields (arrays): the one formula of both paths."""
        c = self.config
        if self.raw or (c.mag_hard_iron == (0.0, 0.0, 0.0) and c.mag_soft_iron == IDENTITY_9):
            return x, y, z
        return calibrated(c.mag_hard_iron, c.mag_soft_iron, x, y, z)

    def prepare_batch(self, mag: ArrayLike | None) -> NDArray[np.float64] | None:
        """Fields (N, 3) for the estimator, NaN rows = none; None when no field at all is passed (the reference of
        :meth:`prepare`)."""
        if mag is None or self.config.use_mag is UseMag.FALSE:
            self.state = FIELD_OFF if self.config.use_mag is UseMag.FALSE else self._missing()
            return None
        raw = np.asarray(mag, dtype=float).reshape(-1, 3)
        with np.errstate(invalid="ignore", over="ignore"):  # a reading that is not finite is no field
            m = np.column_stack(self._calibrated(raw[:, 0], raw[:, 1], raw[:, 2]))
        ok = plausible(m)
        had = np.isfinite(raw).all(axis=1)
        offered = ~np.isnan(raw).all(axis=1)  # a row that holds a reading (NaN rows: none paired)
        self.non_finite += int(np.count_nonzero(offered & ~had))
        self.implausible += int(np.count_nonzero(had & ~ok))
        m = np.where(ok[:, None], m, np.nan)
        if len(m):
            missing = FIELD_STALE if self.seen or ok.any() else FIELD_NONE
            last = FIELD_BAD if had[-1] else (FIELD_NONFINITE if offered[-1] else missing)
            self.state = FIELD_USED if ok[-1] else last
        return m

    def _missing(self) -> str:
        return FIELD_STALE if self.seen else FIELD_NONE

    def prepare(self, mag: ArrayLike | None) -> tuple[float, float, float] | None:
        """:meth:`prepare_batch` for one sample, in plain floats (the node's hot path): the field or None."""
        c = self.config
        if mag is None or c.use_mag is UseMag.FALSE:
            self.state = FIELD_OFF if c.use_mag is UseMag.FALSE else self._missing()
            return None
        x, y, z = _floats(mag)
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
            self.non_finite += 1
            self.state = FIELD_NONFINITE
            return None
        x, y, z = self._calibrated(x, y, z)
        if not USABLE_MIN_T <= math.sqrt(x * x + y * y + z * z) <= USABLE_MAX_T:
            self.implausible += 1
            self.state = FIELD_BAD
            return None
        self.state = FIELD_USED
        return x, y, z

    def note(self, used: bool) -> bool:
        """:meth:`used` for one sample: whether a field has been used since the last reset."""
        if used:
            self.samples_with_field += 1
            self.seen = True
        return self.seen

    def used(self, ok: NDArray[np.bool_]) -> NDArray[np.bool_]:
        """Per row: a field has been used at or before it since the last reset (updates :attr:`seen`)."""
        out = np.logical_or.accumulate(ok) | self.seen if len(ok) else ok
        self.samples_with_field += int(np.count_nonzero(ok))
        if len(out):
            self.seen = bool(out[-1])
        return out

    def declination_applied(self, q: NDArray[np.float64], seen: NDArray[np.bool_]) -> NDArray[np.float64]:
        """Rotate the rows seen with a field by Rz(−declination_deg) (ENU: y becomes true north)."""
        d = self.config.declination_deg
        if d == 0.0 or not seen.any():
            return q
        from riann_ros import quaternion as quat

        out = q.copy()
        out[seen] = quat.multiply(rot_z(-math.radians(d)), q[seen])
        return np.where(out[:, :1] < 0.0, -out, out)
