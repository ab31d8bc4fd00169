"""Perturbations of the signal values (ROS-free): a gyro bias (``bias:``), a gyro scale (``gyro:scale:``, a unit
slip), a magnetometer offset, soft iron or disturbance and a late magnetometer (``magnetic:``). Definitions:
:data:`~riann_ros.evaluation.perturb.conditions.DEFINITIONS`."""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from riann_ros.constants import NS_PER_S
from riann_ros.evaluation.perturb.base import Perturbation, Transform, with_samples
from riann_ros.recording import Recording


# ---------------------------------------------------------------------------------------------------
# bias
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Bias(Perturbation):
    """A constant gyro bias (°/s): fixed per axis, or drawn per sequence with standard deviation ``sigma``."""

    dps: tuple[float, float, float] | None = None
    sigma: float = 0.0
    kind = "bias"

    def text(self) -> str:
        if self.dps is None:
            return f"bias:random:{self.sigma:g}"
        return "bias:" + ",".join(f"{v:g}" for v in self.dps)

    def start(self, rng: np.random.Generator) -> Transform:
        dps = np.asarray(self.dps) if self.dps is not None else rng.normal(0.0, self.sigma, 3)
        return _AddBias(np.radians(dps))


class _AddBias(Transform):
    def __init__(self, bias: NDArray[np.float64]) -> None:
        self.bias = bias

    def __call__(self, rec: Recording) -> Recording:
        return with_samples(rec, gyr=rec.gyr + self.bias)

    def info(self) -> dict[str, Any]:
        return {"bias_dps": np.degrees(self.bias).round(6).tolist()}


# ---------------------------------------------------------------------------------------------------
# gyro scale
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class GyroScale(Perturbation):
    """The gyroscope's values multiplied by ``factor`` from the first sample: a unit slip (deg/s read as rad/s is
    57.2958, mdeg/s as deg/s 0.001)."""

    factor: float = 1.0
    kind = "gyro"

    def text(self) -> str:
        return f"gyro:scale:{self.factor:.12g}"

    def start(self, rng: np.random.Generator) -> Transform:
        return _ScaleGyro(self.factor)


class _ScaleGyro(Transform):
    def __init__(self, factor: float) -> None:
        self.factor = factor
        self.samples = 0

    def __call__(self, rec: Recording) -> Recording:
        self.samples += len(rec)
        return with_samples(rec, gyr=rec.gyr * self.factor)

    def info(self) -> dict[str, Any]:
        return {"factor": self.factor, "samples": self.samples}


# ---------------------------------------------------------------------------------------------------
# magnetic: hard-iron offset, soft iron, disturbance window
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Magnetic(Perturbation):
    """A field added to the magnetometer (µT, sensor frame): constant from the first sample (``offset``),
    or ``strength`` µT in a direction drawn per sequence between ``t0`` and ``t1`` s after it; or a soft iron: the
    reading multiplied by the 3×3 matrix ``soft`` (row-major) from the first sample."""

    offset: tuple[float, float, float] | None = None
    strength: float = 0.0
    t0: float = 0.0
    t1: float = 0.0
    soft: tuple[float, ...] | None = None
    kind = "magnetic"

    def text(self) -> str:
        if self.soft is not None:
            return "magnetic:soft:" + ",".join(f"{v:g}" for v in self.soft)
        if self.offset is not None:
            return "magnetic:offset:" + ",".join(f"{v:g}" for v in self.offset)
        return f"magnetic:disturb:{self.strength:g}@{self.t0:g}-{self.t1:g}s"

    def start(self, rng: np.random.Generator) -> Transform:
        if self.soft is not None:
            return _SoftIron(np.asarray(self.soft, dtype=float).reshape(3, 3))
        if self.offset is not None:
            return _AddField(np.asarray(self.offset, dtype=float) * 1e-6, None)
        d = rng.normal(size=3)
        return _AddField(self.strength * 1e-6 * d / np.linalg.norm(d), (self.t0, self.t1))


class _AddField(Transform):
    def __init__(self, field_t: NDArray[np.float64], window: tuple[float, float] | None) -> None:
        self.field = field_t
        self.window = window
        self.first: int | None = None  # stamp of the sequence's first sample (ns)
        self.samples = 0

    def __call__(self, rec: Recording) -> Recording:
        if rec.mag is None or len(rec) == 0:
            return rec
        if self.first is None:
            self.first = int(rec.stamps_ns[0])
        on = np.ones(len(rec), dtype=bool)
        if self.window is not None:
            t = (rec.stamps_ns - self.first) * 1e-9
            on = (t >= self.window[0]) & (t < self.window[1])
        self.samples += int(on.sum())
        return with_samples(rec, mag=rec.mag + np.where(on[:, None], self.field, 0.0))

    def info(self) -> dict[str, Any]:
        return {"field_uT": (self.field * 1e6).round(6).tolist(), "samples": self.samples}


class _SoftIron(Transform):
    def __init__(self, matrix: NDArray[np.float64]) -> None:
        self.matrix = matrix
        self.samples = 0

    def __call__(self, rec: Recording) -> Recording:
        if rec.mag is None or len(rec) == 0:
            return rec
        self.samples += len(rec)
        return with_samples(rec, mag=rec.mag @ self.matrix.T)

    def info(self) -> dict[str, Any]:
        return {"soft_iron": self.matrix.reshape(9).round(6).tolist(), "samples": self.samples}


# ---------------------------------------------------------------------------------------------------
# magnetic: a late magnetometer
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class MagneticLag(Perturbation):
    """Each field reading carries the field of ``lag`` s earlier under its own stamp (a slow magnetometer driver):
    the field at stamp t is the recording's field at t − lag, linear between the two recording samples around it
    (the earlier one where the later has none); none in the sequence's first ``lag`` s."""

    lag: float = 0.3
    kind = "magnetic"

    def text(self) -> str:
        return f"magnetic:lag:{self.lag * 1e3:g}ms"

    def start(self, rng: np.random.Generator) -> Transform:
        return _LagField(round(self.lag * NS_PER_S))


class _LagField(Transform):
    """Keeps the recording's samples (stamps, fields) from the last at or before the latest lagged time: all that
    a later sample's lagged time can fall between (stamps increase), so any chunking gives the same stream. A stamp
    earlier than the one before it (a clock that went back) starts over: no reading for a lag after it."""

    def __init__(self, lag_ns: int) -> None:
        self.lag_ns = lag_ns
        self.t = np.zeros(0, np.int64)
        self.m = np.zeros((0, 3))
        self.samples = 0
        self.without = 0  # samples given no reading: within a lag of the start (or of a clock going back)

    def __call__(self, rec: Recording) -> Recording:
        if rec.mag is None or len(rec) == 0:
            return rec
        before = self.t[-1:] if len(self.t) else rec.stamps_ns[:1]
        back = np.flatnonzero(np.diff(np.concatenate([before, rec.stamps_ns])) < 0)  # the clock went back: at rec[k]
        out = [self._lagged(rec.stamps_ns[a:b], rec.mag[a:b], a in back)
               for a, b in itertools.pairwise([0, *back[back > 0], len(rec)])]
        self.samples += len(rec)
        return with_samples(rec, mag=np.concatenate(out))

    def _lagged(self, stamps: NDArray[np.int64], mag: NDArray[np.float64], restart: bool) -> NDArray[np.float64]:
        """The fields at ``stamps - lag`` (NaN rows: none), the samples kept for the next piece."""
        if restart:
            self.t, self.m = self.t[:0], self.m[:0]
        t = np.concatenate([self.t, stamps])
        m = np.concatenate([self.m, mag])
        want = stamps - self.lag_ns
        i = np.searchsorted(t, want, side="right") - 1  # the last sample at or before t − lag (-1: none yet)
        out = np.full((len(stamps), 3), np.nan)
        ok = i >= 0
        a, b = i[ok], i[ok] + 1  # b exists: t − lag is before the sample's own stamp, which is in t
        w = ((want[ok] - t[a]) / (t[b] - t[a]))[:, None]
        later = np.isfinite(m[b]).all(axis=1)[:, None]
        out[ok] = np.where(later, m[a] + w * (m[b] - m[a]), m[a])
        keep = max(0, int(i[-1]))
        self.t, self.m = t[keep:], m[keep:]
        self.without += int(np.count_nonzero(~ok))
        return out

    def info(self) -> dict[str, Any]:
        return {"lag_s": self.lag_ns / NS_PER_S, "samples": self.samples, "samples_before_lag": self.without}
