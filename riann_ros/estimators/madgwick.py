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

from numpy.typing import ArrayLike

from riann_ros.estimators.base import Array, AttitudeEstimator, ParamSpec
from riann_ros.estimators.bias import FrontEndSlot, front_end_params
from riann_ros.estimators.common import BIAS_KEY, Quat, as_array, bias_text, initialise, sanitize_arrays

#: ahrs 0.4.0 ``Madgwick`` default ``gain_imu`` (IMU/6D mode); Madgwick's report gives β = √(3/4)·ω̃ with
#: ω̃ the gyro measurement error, and 0.033 corresponds to ω̃ ≈ 2.2°/s.
DEFAULT_BETA = 0.033


def _madgwick_run(q: Quat | None, acc: list, gyr: list, dt: list, beta: float) -> tuple[Quat | None, list]:
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
        *front_end_params(False, "the filter"),
    )

    def reset(self) -> None:
        self._q: Quat | None = None
        self._fe = FrontEndSlot(self.params)

    @property
    def initialized(self) -> bool:
        return self._q is not None

    def diagnostics(self) -> dict[str, str]:
        return {BIAS_KEY: bias_text(self._fe.bias)} if self._fe.on else {}

    def update_batch(self, acc: ArrayLike, gyr: ArrayLike, dt: ArrayLike) -> Array:
        a, g, h = sanitize_arrays(acc, gyr, dt)
        g = self._fe.debias(a, g, h)
        self._q, out = _madgwick_run(self._q, a.tolist(), g.tolist(), h.tolist(), float(self.params["beta"]))
        return as_array(out)
