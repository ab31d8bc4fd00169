"""The estimator interface shared by RIANN, Madgwick, Mahony and VQF (ROS-free).

Every estimator is a causal filter over IMU samples:

* ``update(acc, gyr, dt, mag=None)`` — one sample (acc in m/s², gyr in rad/s, dt in s since the
  previous sample, optionally the magnetic field in the sensor frame) → unit quaternion
  ``[w, x, y, z]``, sensor to world (ENU, z up);
* ``update_batch(acc, gyr, dt, mag=None)`` — a whole sequence ``(N, 3), (N, 3), (N,), (N, 3)`` →
  ``(N, 4)``; it continues from the current state and leaves the state after the last sample, so a
  batch call gives the same numbers as ``N`` calls of ``update`` (tested per estimator);
* ``reset()`` — forget everything; the next sample re-initialises the filter.

**Magnetometer (9D).** ``mag`` is the field in the sensor frame, in tesla (only its direction and its norm
relative to a learned reference matter). ``None`` or a non-finite row means "no field for this sample": the
estimator runs its 6D step and its heading follows the gyro. With a field, the world frame is magnetic ENU
(y = magnetic north); without one, the heading starts at zero. Estimators that use the field set ``USES_MAG``;
:meth:`AttitudeEstimator.heading_observed` says whether the last sample's heading was tied to the field (the node
reports a finite yaw covariance only then). The field an estimator gets is calibrated: by the stream with the
configured calibration, or, where the online calibration is on, by the magnetometer's front end
(:class:`~riann_ros.magcal.frontend.MagFrontEnd`) that the stream gives the estimator
(:meth:`AttitudeEstimator.take_front_end`): the estimator then hands it the raw field with its gyro and takes back
the calibrated field, its σ and the change events, never touching the calibration itself. Without a front end the
field is used as it is given.

A subclass implements ``reset`` and at least one of ``update`` / ``update_batch``: the base class
derives the other (one sample as a batch of one, or a batch as a loop of samples). Construction
validates the parameters and calls ``reset()``.

**Uncertainty.** :meth:`AttitudeEstimator.sigma` gives, per sample of the last ``update`` /
``update_batch`` call, the standard deviations (rad) of the inclination (roll and pitch errors as an
isotropic 2-D Gaussian: σ per horizontal axis) and of the heading. The default is a documented
constant: :data:`~riann_ros.defaults.INCLINATION_SD_DEG`, and the heading
:data:`~riann_ros.defaults.YAW_FREE_SD_DEG` without a field or :data:`~riann_ros.defaults.MAG_HEADING_SD_DEG` with
one (the classical filters add the calibration's share, :mod:`~riann_ros.estimators.classical`); RIANN reports its
per-sample model.
:meth:`AttitudeEstimator.heading_state` may say per sample whether a field corrected the heading or the gyro
held it (the evaluator then splits the heading's uncertainty scores by it; default: not said).

Parameters are described by :class:`~riann_ros.params.ParamSpec` so that the ROS node base can declare
them (with description, range and whether they can change at run time) without knowing the estimator,
and the evaluator can list, parse and grid-search them.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from riann_ros.defaults import INCLINATION_SD_DEG, MAG_HEADING_SD_DEG, YAW_FREE_SD_DEG
from riann_ros.magcal.frontend import LatencySettings, MagFrontEnd
from riann_ros.params import ParamSpec, find

Array = NDArray[np.float64]

__all__ = ["HEADING_CORRECTED", "HEADING_HELD", "HEADING_UNKNOWN", "Array", "AttitudeEstimator", "ParamSpec"]


#: the codes of :meth:`AttitudeEstimator.heading_state`
HEADING_UNKNOWN, HEADING_CORRECTED, HEADING_HELD = 0.0, 1.0, 2.0


class AttitudeEstimator(ABC):
    """Base class of all attitude estimators. Subclasses set ``name`` and ``PARAMS``."""

    name: ClassVar[str] = ""
    PARAMS: ClassVar[tuple[ParamSpec, ...]] = ()
    USES_MAG: ClassVar[bool] = False

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
        self.front: MagFrontEnd | None = None  # the magnetometer's front end (take_front_end); kept over reset()
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

    # -- the magnetometer's front end (docs/magnetometer.md) ---------------------------------------------------------
    def take_front_end(self, front: MagFrontEnd) -> None:
        """The stream's magnetometer front end (the field's calibration, latency and tilt, :mod:`riann_ros.magcal`):
        from now on the estimator hands it the raw field, where it calibrates online (``front.calibrating``), and
        takes back the calibrated field. Kept over :meth:`reset` (the calibration is the robot's)."""
        self.front = front
        front.latency_settings = self.front_end_latency()

    def front_end_latency(self) -> LatencySettings:
        """What the estimator does with the magnetometer's latency (the front end's :class:`LatencySettings`).
        Default: estimated for the calibration's windows only, the field used as it comes."""
        return LatencySettings()

    # -- estimation -----------------------------------------------------------------------------
    @abstractmethod
    def reset(self) -> None:
        """Forget the state; the next sample initialises the filter again."""

    def on_gap(self) -> None:
        """The stream resumes after a stamp gap longer than the gate's ``max_dt`` (messages lost, the
        sensor the same). Default: :meth:`reset`; an estimator may keep what the gap does not change."""
        self.reset()

    def heading_observed(self) -> bool:
        """True while the heading is tied to the magnetic field (the last sample's field was used and
        not rejected as disturbed); False for 6D estimators and while the heading follows the gyro."""
        return False

    def heading_state(self) -> Array | None:
        """(n,) for the samples of the last call, what the estimator says of its heading: :data:`HEADING_CORRECTED`
        where a field corrected it, :data:`HEADING_HELD` where the gyro held it after one (the field rejected or
        absent), :data:`HEADING_UNKNOWN` where it is not known. None (the default): the estimator does not say, and
        the evaluator splits the heading's samples by their σ."""
        return None

    def sigma(self, fields: NDArray[np.bool_]) -> Array:
        """(n, 2): σ (rad) of the inclination per horizontal axis and of the heading, for the n samples of the last
        :meth:`update` / :meth:`update_batch` call; ``fields`` (n,): which of them carried a field the estimator
        got. Default: the documented constants (see the module docstring); the heading's σ with a field only for
        estimators that use it (``USES_MAG``). Never changes the state."""
        f = np.asarray(fields, dtype=bool) & self.USES_MAG
        yaw = np.where(f, np.radians(MAG_HEADING_SD_DEG), np.radians(YAW_FREE_SD_DEG))
        return np.column_stack([np.full(len(f), np.radians(INCLINATION_SD_DEG)), yaw])

    def update(self, acc: ArrayLike, gyr: ArrayLike, dt: float, mag: ArrayLike | None = None) -> Array:
        """Process one sample and return the attitude quaternion ``[w, x, y, z]``."""
        m = None if mag is None else np.reshape(np.asarray(mag, dtype=float), (1, 3))
        return self.update_batch(np.reshape(acc, (1, 3)), np.reshape(gyr, (1, 3)), [dt], m)[0]

    def update_batch(self, acc: ArrayLike, gyr: ArrayLike, dt: ArrayLike, mag: ArrayLike | None = None) -> Array:
        """Process a sequence (a loop over :meth:`update` unless a subclass vectorises it)."""
        acc = np.asarray(acc, dtype=float)
        gyr = np.asarray(gyr, dtype=float)
        dt = np.broadcast_to(np.asarray(dt, dtype=float), (len(acc),))
        m = None if mag is None else np.asarray(mag, dtype=float).reshape(-1, 3)
        out = np.empty((len(acc), 4))
        for i in range(len(acc)):
            out[i] = self.update(acc[i], gyr[i], float(dt[i]), None if m is None else m[i])
        return out
