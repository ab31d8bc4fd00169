"""Madgwick's gradient-descent attitude filter, IMU (6D) form, in plain Python (ROS-free).

S. O. H. Madgwick, "An efficient orientation filter for inertial and inertial/magnetic sensor
arrays", 2010; IMU update as in Madgwick's reference code and in ``ahrs.filters.Madgwick.updateIMU``:

    q̇ = ½ q ⊗ [0, ω] − β ∇f / ‖∇f‖,   f(q, â) = R(q)ᵀ e_z − â,   q ← normalise(q + q̇ dt)

with ``â`` the normalised accelerometer sample. ``q`` is sensor → world with world z up (ENU): at rest
the accelerometer reads +g along the world z axis seen from the sensor, ``R(q)ᵀ e_z``.

Conventions shared with :mod:`riann_ros.estimators.mahony`:

* **initialisation** — the first sample with a finite, non-zero accelerometer sets the attitude with
  :func:`riann_ros.quaternion.from_accelerometer` (zero heading) and is output as it is (its gyro and dt
  are not integrated: there is no previous sample). Samples before that return the identity.
* **per-sample dt** — each step integrates over its own ``dt``; non-finite or negative dt counts as 0.
* **degenerate input** — a zero (or non-finite) accelerometer sample gives a gyro-only step, as in
  Madgwick's reference code; a non-finite gyro sample counts as zero rate. If a step ever produced a
  non-finite or zero quaternion the previous one is kept, so the output is always a finite unit
  quaternion. (Unlike ``ahrs``, a gyro sample of exactly zero still gets the accelerometer correction;
  ``ahrs`` skips such samples entirely.)
* **speed** — the recursion cannot be vectorised over time, so the loop runs on Python floats in local
  variables (no numpy per sample). :meth:`update` runs the very same loop with one sample, so
  streaming and batch give identical numbers.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from riann_ros import quaternion as quat
from riann_ros.estimators.base import Array, AttitudeEstimator, ParamSpec

#: ahrs 0.4.0 ``Madgwick`` default ``gain_imu`` (IMU/6D mode); Madgwick's report gives β = √(3/4)·ω̃ with
#: ω̃ the gyro measurement error, and 0.033 corresponds to ω̃ ≈ 2.2°/s.
DEFAULT_BETA = 0.033


def sanitize_arrays(acc: ArrayLike, gyr: ArrayLike, dt: ArrayLike) -> tuple[Array, Array, Array]:
    """Copies of the inputs as ``(N, 3), (N, 3), (N,)`` float arrays, degenerate values neutralised.

    Non-finite acc rows → zeros (gyro-only step), non-finite gyr rows → zeros, non-finite or negative
    dt → 0. ``dt`` may be a scalar (broadcast).
    """
    acc = np.array(acc, dtype=float, copy=True).reshape(-1, 3)
    gyr = np.array(gyr, dtype=float, copy=True).reshape(-1, 3)
    n = len(acc)
    if gyr.shape != (n, 3):
        raise ValueError(f"acc and gyr must have the same number of samples, got {acc.shape} and {gyr.shape}")
    dt = np.array(np.broadcast_to(np.asarray(dt, dtype=float), (n,)), dtype=float)
    acc[~np.isfinite(acc).all(axis=1)] = 0.0
    gyr[~np.isfinite(gyr).all(axis=1)] = 0.0
    dt[~(np.isfinite(dt) & (dt > 0.0))] = 0.0
    return acc, gyr, dt


def sanitize(acc: ArrayLike, gyr: ArrayLike, dt: ArrayLike) -> tuple[list, list, list]:
    """:func:`sanitize_arrays` as nested lists of Python floats, for the per-sample loops."""
    a, g, h = sanitize_arrays(acc, gyr, dt)
    return a.tolist(), g.tolist(), h.tolist()


def initialise(q: tuple[float, float, float, float] | None, acc: list, out: list
               ) -> tuple[tuple[float, float, float, float] | None, int]:
    """Until the first usable accelerometer sample sets the attitude, output the identity.

    Returns the attitude (None when no sample was usable) and the index of the first sample to
    filter; the outputs of the samples consumed are appended to ``out``.
    """
    i = 0
    while q is None and i < len(acc):
        q = initial_attitude(*acc[i])
        out.append(q if q is not None else (1.0, 0.0, 0.0, 0.0))
        i += 1
    return q, i


def initial_attitude(ax: float, ay: float, az: float) -> tuple[float, float, float, float] | None:
    """Zero-heading attitude from one accelerometer sample, or None when it carries no direction."""
    if not (ax * ax + ay * ay + az * az > 0.0):
        return None
    w, x, y, z = quat.from_accelerometer([ax, ay, az]).tolist()
    return w, x, y, z


def _madgwick_run(
    q: tuple[float, float, float, float] | None, acc: list, gyr: list, dt: list, beta: float
) -> tuple[tuple[float, float, float, float] | None, list]:
    """Run the filter from state ``q`` (None = not initialised) over the samples; (new q, outputs)."""
    out: list = []
    append = out.append
    sqrt = math.sqrt
    inf = math.inf
    q, i = initialise(q, acc, out)
    if q is None:
        return None, out
    qw, qx, qy, qz = q
    for (ax, ay, az), (gx, gy, gz), h in zip(acc[i:], gyr[i:], dt[i:], strict=True):
        # rate of change from the gyroscope: ½ q ⊗ [0, ω]
        dw = 0.5 * (-qx * gx - qy * gy - qz * gz)
        dx = 0.5 * (qw * gx + qy * gz - qz * gy)
        dy = 0.5 * (qw * gy - qx * gz + qz * gx)
        dz = 0.5 * (qw * gz + qx * gy - qy * gx)
        an = sqrt(ax * ax + ay * ay + az * az)
        if an > 0.0:
            ax /= an
            ay /= an
            az /= an
            # objective f = R(q)ᵀ e_z − â and gradient Jᵀ f
            f1 = 2.0 * (qx * qz - qw * qy) - ax
            f2 = 2.0 * (qw * qx + qy * qz) - ay
            f3 = 2.0 * (0.5 - qx * qx - qy * qy) - az
            s0 = -2.0 * qy * f1 + 2.0 * qx * f2
            s1 = 2.0 * qz * f1 + 2.0 * qw * f2 - 4.0 * qx * f3
            s2 = -2.0 * qw * f1 + 2.0 * qz * f2 - 4.0 * qy * f3
            s3 = 2.0 * qx * f1 + 2.0 * qy * f2
            sn = sqrt(s0 * s0 + s1 * s1 + s2 * s2 + s3 * s3)
            if 0.0 < sn < inf:
                k = beta / sn
                dw -= k * s0
                dx -= k * s1
                dy -= k * s2
                dz -= k * s3
        nw = qw + dw * h
        nx = qx + dx * h
        ny = qy + dy * h
        nz = qz + dz * h
        nn = sqrt(nw * nw + nx * nx + ny * ny + nz * nz)
        if 0.0 < nn < inf:
            qw = nw / nn
            qx = nx / nn
            qy = ny / nn
            qz = nz / nn
        append((qw, qx, qy, qz))
    return (qw, qx, qy, qz), out


def as_array(rows: list) -> Array:
    """(N, 4) array from a list of 4-tuples (also for N = 0)."""
    return np.array(rows, dtype=float).reshape(-1, 4)


class MadgwickEstimator(AttitudeEstimator):
    """Madgwick IMU filter with gain ``beta``; see the module docstring."""

    name = "madgwick"
    PARAMS = (
        ParamSpec(
            "beta",
            DEFAULT_BETA,
            "Gradient-descent gain β (rad/s): weight of the accelerometer correction. Default 0.033 = the "
            "ahrs 0.4.0 default for IMU (6D) mode; the BROAD authors' tuned 9D value is 0.12.",
            min=0.0,
            max=10.0,
            runtime=True,
        ),
    )

    def __init__(self, **params: object) -> None:
        super().__init__(**params)
        self.reset()

    def reset(self) -> None:
        self._q: tuple[float, float, float, float] | None = None

    @property
    def initialized(self) -> bool:
        return self._q is not None

    def update(self, acc: ArrayLike, gyr: ArrayLike, dt: float) -> Array:
        return self.update_batch(np.reshape(acc, (1, 3)), np.reshape(gyr, (1, 3)), [dt])[0]

    def update_batch(self, acc: ArrayLike, gyr: ArrayLike, dt: ArrayLike) -> Array:
        a, g, h = sanitize(acc, gyr, dt)
        self._q, out = _madgwick_run(self._q, a, g, h, float(self.params["beta"]))
        return as_array(out)
