"""Madgwick's gradient-descent attitude filter, IMU (6D) and MARG (9D) forms, in plain Python (ROS-free).

S. O. H. Madgwick, "An efficient orientation filter for inertial and inertial/magnetic sensor
arrays", 2010; IMU update as in Madgwick's reference code and in ``ahrs.filters.Madgwick.updateIMU``:

    q̇ = ½ q ⊗ [0, ω] − β ∇f / ‖∇f‖,   f(q, â) = R(q)ᵀ e_z − â,   q ← normalise(q + q̇ dt)

with ``â`` the normalised accelerometer sample. ``q`` is sensor → world with world z up (ENU): at rest
the accelerometer reads +g along the world z axis seen from the sensor, ``R(q)ᵀ e_z``.

**MARG (9D) form**, used when ``mag`` is given (Madgwick 2010 eqs. 45-46, as ``ahrs.filters.Madgwick.updateMARG``):
the objective gets the magnetometer rows

    f = [R(q)ᵀ e_z − â ;  R(q)ᵀ (b_x, 0, b_z) − m̂],   h = R(q) m̂,   b_x = √(h_x² + h_y²),   b_z = h_z

with ``m̂`` the normalised field and gain ``beta_marg`` (default 0.041, the ahrs 0.4.0 ``gain_marg``).
Madgwick's reference field (b_x, 0, b_z) puts magnetic north on the earth *x* axis: his earth frame is
NWU (x north, y west, z up), while this package's is ENU (x east, y north, z up). The recursion therefore
runs on ``q_NWU = C⁻¹ ⊗ q_ENU`` and every output is ``q_ENU = C ⊗ q_NWU`` with ``C`` = +90° about z
(:data:`C_NWU_TO_ENU`). The objective is deliberately not rewritten for ENU: Madgwick's polynomial
objective equals the rotation only on the unit sphere, and a world-rotated version has a different radial
gradient component, which changes ∇f/‖∇f‖ (up to ~1e-3 per component on BROAD); in his frame the numbers
equal ``ahrs`` to round-off. The state kept between calls is the NWU quaternion itself, so streaming and
batch stay identical. Samples without a field (non-finite or all-zero ``mag`` row) get the IMU step above
with ``beta`` (in the NWU frame; the 6D objective is invariant under rotations about world z, so this is
the 6D filter up to round-off); ``ahrs`` instead calls ``updateIMU`` with its single gain and its
default ``Dt``. Initialisation with a field: :func:`~riann_ros.estimators.common.initial_attitude_marg`
(accelerometer attitude, heading from the tilt-compensated field: its horizontal part along +y).
:meth:`MadgwickEstimator.heading_observed` is True iff the last sample's correction used a field. Where the online
magnetometer calibration changes the calibration the field gets and the heading disagrees with the new one, the
heading is set from the field as at the start (:mod:`~riann_ros.magcal.changes`).

Conventions shared with :mod:`riann_ros.estimators.mahony`:

* **initialisation** — the first sample with a finite, non-zero accelerometer sets the attitude with
  :func:`riann_ros.quaternion.from_accelerometer` (zero heading; with ``mag`` and a field in that sample,
  the heading of the field) and is output as it is (its gyro and dt are not integrated: there is no
  previous sample). Samples before that return the identity.
* **per-sample dt** — each step integrates over its own ``dt``; non-finite or negative dt counts as 0.
* **degenerate input** — a zero (or non-finite) accelerometer sample gives a gyro-only step, as in
  Madgwick's reference code (no magnetometer correction either, as ``ahrs``); a non-finite gyro sample
  counts as zero rate. If a step ever produced a non-finite or zero quaternion the previous one is kept, so
  the output is always a finite unit quaternion. (Unlike ``ahrs``, a gyro sample of exactly zero still
  gets the accelerometer (and magnetometer) correction; ``ahrs`` skips such samples entirely.)
* **speed** — the recursion cannot be vectorised over time, so the loop runs on Python floats in local
  variables (no numpy per sample). One loop serves both forms (without ``mag`` every sample takes the IMU step,
  here on the ENU state). :meth:`update` runs the very same loop with one sample, so streaming and batch give
  identical numbers.
"""

from __future__ import annotations

import math

from riann_ros.estimators.base import Array, ParamSpec
from riann_ros.estimators.bias import FrontEndSlot, front_end_params
from riann_ros.estimators.classical import Batch, ClassicalFilter
from riann_ros.estimators.common import BIAS_KEY, Quat, Rows, as_array, bias_text, initialise, realigned
from riann_ros.magcal.input import MAG_CAL_PARAMS

#: ahrs 0.4.0 ``Madgwick`` default ``gain_imu`` (IMU/6D mode); Madgwick's report gives β = √(3/4)·ω̃ with
#: ω̃ the gyro measurement error, and 0.033 corresponds to ω̃ ≈ 2.2°/s.
DEFAULT_BETA = 0.033
#: ahrs 0.4.0 ``Madgwick`` default ``gain_marg`` (MARG/9D mode, samples with a field).
DEFAULT_BETA_MARG = 0.041

_C = math.sqrt(0.5)
#: ``q_ENU = C ⊗ q_NWU``: Madgwick's MARG earth frame NWU (x magnetic north, y west, z up) → ENU is +90° about z.
C_NWU_TO_ENU: Quat = (_C, 0.0, 0.0, _C)


def enu_to_nwu(q: Quat) -> Quat:
    """``C⁻¹ ⊗ q`` (:data:`C_NWU_TO_ENU`): a sensor → ENU attitude as sensor → NWU."""
    w, x, y, z = q
    return _C * (w + z), _C * (x + y), _C * (y - x), _C * (z - w)


def nwu_to_enu(q: Quat) -> Quat:
    """``C ⊗ q`` (:data:`C_NWU_TO_ENU`): a sensor → NWU attitude as sensor → ENU."""
    w, x, y, z = q
    return _C * (w - z), _C * (x - y), _C * (y + x), _C * (z + w)


def _madgwick_loop(q: Quat, used: bool, rows: Rows, beta: float, beta_marg: float,
                   nwu: bool) -> tuple[Quat, bool, list]:
    """The filter from the attitude ``q`` (sensor → NWU when ``nwu``, else sensor → ENU) over the samples: the MARG
    step with ``beta_marg`` where a ``mag`` row has a field, the IMU step with ``beta`` elsewhere. ``used`` is the
    heading-observed flag before the samples; returns (new q in its frame, whether the last sample's correction
    used a field, ENU outputs)."""
    out: list = []
    append = out.append
    sqrt = math.sqrt
    inf = math.inf
    c = _C
    qw, qx, qy, qz = q
    for (ax, ay, az), (gx, gy, gz), m, h in zip(rows.acc, rows.gyr, rows.mag, rows.dt, strict=True):
        # rate of change from the gyroscope: ½ q ⊗ [0, ω]
        dw, dx = 0.5 * (-qx * gx - qy * gy - qz * gz), 0.5 * (qw * gx + qy * gz - qz * gy)
        dy, dz = 0.5 * (qw * gy - qx * gz + qz * gx), 0.5 * (qw * gz + qx * gy - qy * gx)
        used = False
        an = sqrt(ax * ax + ay * ay + az * az)
        if an > 0.0:
            ax, ay, az = ax / an, ay / an, az / an
            # accelerometer rows of the objective f = R(q)ᵀ e_z − â and of the gradient Jᵀ f
            f1, f2 = 2.0 * (qx * qz - qw * qy) - ax, 2.0 * (qw * qx + qy * qz) - ay
            f3 = 2.0 * (0.5 - qx * qx - qy * qy) - az
            s0, s1 = -2.0 * qy * f1 + 2.0 * qx * f2, 2.0 * qz * f1 + 2.0 * qw * f2 - 4.0 * qx * f3
            s2, s3 = -2.0 * qw * f1 + 2.0 * qz * f2 - 4.0 * qy * f3, 2.0 * qx * f1 + 2.0 * qy * f2
            k = beta
            if m is not None and 0.0 < (mn := m[0] * m[0] + m[1] * m[1] + m[2] * m[2]) < inf:
                used, k = True, beta_marg
                mn = sqrt(mn)
                mx, my, mz = m[0] / mn, m[1] / mn, m[2] / mn
                # h = q ⊗ m̂ ⊗ q* (earth frame, as riann_ros.rotations.rotate), reference field (b_x, 0, b_z)
                tx, ty, tz = 2.0 * (qy * mz - qz * my), 2.0 * (qz * mx - qx * mz), 2.0 * (qx * my - qy * mx)
                hx, hy = mx + qw * tx + (qy * tz - qz * ty), my + qw * ty + (qz * tx - qx * tz)
                bx, bz = sqrt(hx * hx + hy * hy), mz + qw * tz + (qx * ty - qy * tx)
                # magnetometer rows of f and of Jᵀ f (Madgwick 2010 eqs. 29-34)
                f4 = 2.0 * bx * (0.5 - qy * qy - qz * qz) + 2.0 * bz * (qx * qz - qw * qy) - mx
                f5 = 2.0 * bx * (qx * qy - qw * qz) + 2.0 * bz * (qw * qx + qy * qz) - my
                f6 = 2.0 * bx * (qw * qy + qx * qz) + 2.0 * bz * (0.5 - qx * qx - qy * qy) - mz
                s0 += -2.0 * bz * qy * f4 + (-2.0 * bx * qz + 2.0 * bz * qx) * f5 + 2.0 * bx * qy * f6
                s1 += 2.0 * bz * qz * f4 + (2.0 * bx * qy + 2.0 * bz * qw) * f5 + (2.0 * bx * qz - 4.0 * bz * qx) * f6
                s2 += ((-4.0 * bx * qy - 2.0 * bz * qw) * f4 + (2.0 * bx * qx + 2.0 * bz * qz) * f5
                       + (2.0 * bx * qw - 4.0 * bz * qy) * f6)
                s3 += (-4.0 * bx * qz + 2.0 * bz * qx) * f4 + (-2.0 * bx * qw + 2.0 * bz * qy) * f5 + 2.0 * bx * qx * f6
            # gradient step β ∇f / ‖∇f‖
            sn = sqrt(s0 * s0 + s1 * s1 + s2 * s2 + s3 * s3)
            if 0.0 < sn < inf:
                k /= sn
                dw, dx = dw - k * s0, dx - k * s1
                dy, dz = dy - k * s2, dz - k * s3
        # q ← normalise(q + q̇ dt), the previous q where that is not finite
        nw, nx = qw + dw * h, qx + dx * h
        ny, nz = qy + dy * h, qz + dz * h
        nn = sqrt(nw * nw + nx * nx + ny * ny + nz * nz)
        if 0.0 < nn < inf:
            qw, qx = nw / nn, nx / nn
            qy, qz = ny / nn, nz / nn
        # the ENU output: q_ENU = C ⊗ q_NWU
        append((c * (qw - qz), c * (qx - qy), c * (qy + qx), c * (qz + qw)) if nwu else (qw, qx, qy, qz))
    return (qw, qx, qy, qz), used, out


class MadgwickEstimator(ClassicalFilter):
    """Madgwick IMU/MARG filter with gains ``beta`` (no field) and ``beta_marg`` (field); see the module docstring."""

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
        ParamSpec(
            "beta_marg",
            DEFAULT_BETA_MARG,
            "Gradient-descent gain β (rad/s) for samples with a magnetometer field (MARG/9D mode): weight of the "
            "accelerometer and magnetometer correction. Default 0.041 = the ahrs 0.4.0 default (gain_marg).",
            min=0.0,
            max=10.0,
            runtime=True,
        ),
        *MAG_CAL_PARAMS,
        *front_end_params(False, "the filter"),
    )

    def _reset_filter(self) -> None:
        self._q: Quat | None = None  # sensor → ENU, the last output
        # (ENU state, the same attitude in NWU) as the last 9D call left them: the NWU value continues exactly
        self._marg: tuple[Quat, Quat] | None = None
        self._observed = False
        self._fe = FrontEndSlot(self.params)

    def diagnostics(self) -> dict[str, str]:
        return {BIAS_KEY: bias_text(self._fe.bias)} if self._fe.on else {}

    def heading_observed(self) -> bool:
        return self._observed

    def _debiased(self, acc: Array, gyr: Array, dt: Array) -> Array:
        return self._fe.debias(acc, gyr, dt)

    def _run(self, batch: Batch) -> Array:
        al, gl, hl = batch.as_lists()
        nine = batch.mag is not None
        rows = Rows(al, gl, batch.mag if batch.mag is not None else [None] * len(al), hl, batch.realign)
        out: list = []
        state, used = (self._nwu_state() if nine else self._q), self._observed
        if state is None:
            q0, rows, used = initialise(rows, out)
            state = enu_to_nwu(q0) if nine and q0 is not None else q0
        if state is not None:
            beta, beta_marg = float(self.params["beta"]), float(self.params["beta_marg"])
            for piece, sd in rows.pieces():
                if sd is not None:  # the calibration changed (the state is sensor → NWU)
                    state = enu_to_nwu(realigned(nwu_to_enu(state), piece.mag[0], sd))
                state, used, filtered = _madgwick_loop(state, used, piece, beta, beta_marg, nine)
                out += filtered
            self._q = out[-1] if out else self._q
            self._marg = (self._q, state) if nine and self._q is not None else None
        self._observed = used
        return as_array(out)

    def _nwu_state(self) -> Quat | None:
        """The state as sensor → NWU: the last 9D call's own value while the attitude is the one it left."""
        if self._q is None:
            return None
        if self._marg is not None and self._marg[0] == self._q:
            return self._marg[1]
        return enu_to_nwu(self._q)
