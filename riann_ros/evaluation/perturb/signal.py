"""Perturbations of the signal values (ROS-free): a gyro bias (``bias:``) and a magnetometer offset or disturbance
(``magnetic:``). Definitions: :data:`~riann_ros.evaluation.perturb.conditions.DEFINITIONS`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

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
