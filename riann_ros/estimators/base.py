"""The estimator interface shared by RIANN, Madgwick, Mahony and VQF (ROS-free).

Every estimator is a causal filter over IMU samples:

* ``update(acc, gyr, dt)`` — one sample (acc in m/s², gyr in rad/s, dt in s since the previous
  sample) → unit quaternion ``[w, x, y, z]``, sensor to world (ENU, z up);
* ``update_batch(acc, gyr, dt)`` — a whole sequence ``(N, 3), (N, 3), (N,)`` → ``(N, 4)``; it
  continues from the current state and leaves the state after the last sample, so a batch call gives
  the same numbers as ``N`` calls of ``update`` (tested per estimator);
* ``reset()`` — forget everything; the next sample re-initialises the filter.

Parameters are described by :class:`ParamSpec` so that the ROS node base can declare them (with
description, range and whether they can change at run time) without knowing the estimator, and the
evaluator can list and grid-search them.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]


@dataclass(frozen=True)
class ParamSpec:
    """One estimator parameter: what the node declares and the evaluator can tune."""

    name: str
    default: float | bool | str
    description: str
    min: float | None = None
    max: float | None = None
    runtime: bool = False  # may change while running (validated), without a reset

    def validate(self, value: Any) -> Any:
        """Return ``value`` converted to the parameter's type, or raise ``ValueError``."""
        if isinstance(self.default, bool):
            if not isinstance(value, bool):
                raise ValueError(f"{self.name} must be a bool, got {value!r}")
            return value
        if isinstance(self.default, str):
            if not isinstance(value, str):
                raise ValueError(f"{self.name} must be a string, got {value!r}")
            return value
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"{self.name} must be a number, got {value!r}")
        v = float(value)
        if not np.isfinite(v):
            raise ValueError(f"{self.name} must be finite, got {value!r}")
        if self.min is not None and v < self.min:
            raise ValueError(f"{self.name}={v} is below its minimum {self.min}")
        if self.max is not None and v > self.max:
            raise ValueError(f"{self.name}={v} is above its maximum {self.max}")
        return v


class AttitudeEstimator(ABC):
    """Base class of all attitude estimators. Subclasses set ``name`` and ``PARAMS``."""

    name: ClassVar[str] = ""
    PARAMS: ClassVar[tuple[ParamSpec, ...]] = ()

    def __init__(self, **params: Any) -> None:
        specs = {p.name: p for p in self.PARAMS}
        unknown = set(params) - set(specs)
        if unknown:
            raise ValueError(
                f"unknown parameter(s) for {self.name}: {', '.join(sorted(unknown))}; "
                f"known: {', '.join(specs) or 'none'}"
            )
        self.params: dict[str, Any] = {p.name: p.default for p in self.PARAMS}
        for key, value in params.items():
            self.params[key] = specs[key].validate(value)

    # -- parameters -----------------------------------------------------------------------------
    @classmethod
    def param_spec(cls, name: str) -> ParamSpec:
        for p in cls.PARAMS:
            if p.name == name:
                return p
        raise KeyError(name)

    def set_params(self, **params: Any) -> None:
        """Change parameters while running; only those with ``runtime=True`` (validated)."""
        for key, value in params.items():
            spec = self.param_spec(key)
            if not spec.runtime:
                raise ValueError(f"{self.name}: parameter {key} cannot change at run time")
            self.params[key] = spec.validate(value)
        self._on_params_changed()

    def _on_params_changed(self) -> None:  # noqa: B027 - optional hook, default does nothing
        """Hook for subclasses that cache derived values of their parameters."""

    # -- estimation -----------------------------------------------------------------------------
    @abstractmethod
    def reset(self) -> None:
        """Forget the state; the next sample initialises the filter again."""

    @abstractmethod
    def update(self, acc: ArrayLike, gyr: ArrayLike, dt: float) -> Array:
        """Process one sample and return the attitude quaternion ``[w, x, y, z]``."""

    def update_batch(self, acc: ArrayLike, gyr: ArrayLike, dt: ArrayLike) -> Array:
        """Process a sequence; the default loops over :meth:`update`. Subclasses vectorise."""
        acc = np.asarray(acc, dtype=float)
        gyr = np.asarray(gyr, dtype=float)
        dt = np.broadcast_to(np.asarray(dt, dtype=float), (len(acc),))
        out = np.empty((len(acc), 4))
        for i in range(len(acc)):
            out[i] = self.update(acc[i], gyr[i], float(dt[i]))
        return out

    def describe(self) -> str:
        """Readable label with the non-default parameters, e.g. ``madgwick(beta=0.1)``."""
        diff = {k: v for k, v in self.params.items() if v != self.param_spec(k).default}
        if not diff:
            return self.name
        inner = ", ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in diff.items())
        return f"{self.name}({inner})"
