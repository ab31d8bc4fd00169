"""The estimator interface shared by RIANN, Madgwick, Mahony and VQF (ROS-free).

Every estimator is a causal filter over IMU samples:

* ``update(acc, gyr, dt)`` — one sample (acc in m/s², gyr in rad/s, dt in s since the previous
  sample) → unit quaternion ``[w, x, y, z]``, sensor to world (ENU, z up);
* ``update_batch(acc, gyr, dt)`` — a whole sequence ``(N, 3), (N, 3), (N,)`` → ``(N, 4)``; it
  continues from the current state and leaves the state after the last sample, so a batch call gives
  the same numbers as ``N`` calls of ``update`` (tested per estimator);
* ``reset()`` — forget everything; the next sample re-initialises the filter.

A subclass implements ``reset`` and at least one of ``update`` / ``update_batch``: the base class
derives the other (one sample as a batch of one, or a batch as a loop of samples). Construction
validates the parameters and calls ``reset()``.

Parameters are described by :class:`~riann_ros.params.ParamSpec` so that the ROS node base can declare
them (with description, range and whether they can change at run time) without knowing the estimator,
and the evaluator can list, parse and grid-search them.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from riann_ros.params import ParamSpec, find

Array = NDArray[np.float64]

__all__ = ["Array", "AttitudeEstimator", "ParamSpec"]


class AttitudeEstimator(ABC):
    """Base class of all attitude estimators. Subclasses set ``name`` and ``PARAMS``."""

    name: ClassVar[str] = ""
    PARAMS: ClassVar[tuple[ParamSpec, ...]] = ()

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if cls.update is AttitudeEstimator.update and cls.update_batch is AttitudeEstimator.update_batch:
            raise TypeError(f"{cls.__name__} must implement update or update_batch")

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
        self.reset()

    # -- parameters -----------------------------------------------------------------------------
    @classmethod
    def param_spec(cls, name: str) -> ParamSpec:
        return find(cls.PARAMS, name)

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

    def diagnostics(self) -> dict[str, str]:
        """Estimator-specific values for the node's ``/diagnostics`` (e.g. its gyro-bias estimate)."""
        return {}

    # -- estimation -----------------------------------------------------------------------------
    @abstractmethod
    def reset(self) -> None:
        """Forget the state; the next sample initialises the filter again."""

    def on_gap(self) -> None:
        """The stream resumes after a stamp gap longer than the gate's ``max_dt`` (messages lost, the
        sensor the same). Default: :meth:`reset`; an estimator may keep what the gap does not change."""
        self.reset()

    def update(self, acc: ArrayLike, gyr: ArrayLike, dt: float) -> Array:
        """Process one sample and return the attitude quaternion ``[w, x, y, z]``."""
        return self.update_batch(np.reshape(acc, (1, 3)), np.reshape(gyr, (1, 3)), [dt])[0]

    def update_batch(self, acc: ArrayLike, gyr: ArrayLike, dt: ArrayLike) -> Array:
        """Process a sequence (a loop over :meth:`update` unless a subclass vectorises it)."""
        acc = np.asarray(acc, dtype=float)
        gyr = np.asarray(gyr, dtype=float)
        dt = np.broadcast_to(np.asarray(dt, dtype=float), (len(acc),))
        out = np.empty((len(acc), 4))
        for i in range(len(acc)):
            out[i] = self.update(acc[i], gyr[i], float(dt[i]))
        return out
