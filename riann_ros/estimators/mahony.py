"""Mahony's explicit complementary filter, IMU (6D) and MARG (9D) forms, in plain Python (ROS-free).

R. Mahony, T. Hamel, J.-M. Pflimlin, "Nonlinear complementary filters on the special orthogonal
group", IEEE TAC 53(5), 2008; quaternion form as in ``ahrs.filters.Mahony.updateIMU``:

    v = R(q)ᵀ e_z,   e = â × v,   b ← b − k_I e dt,   Ω = ω − b + k_P e,
    q ← normalise(q + ½ q ⊗ [0, Ω] dt)

with ``â`` the normalised accelerometer sample and ``b`` the gyro-bias estimate (integral term,
starts at zero, cleared by :meth:`~MahonyEstimator.reset`). ``q`` is sensor → world, world z up (ENU).

**MARG (9D) form**, used when ``mag`` is given (as ``ahrs.filters.Mahony.updateMARG``): with ``m̂`` the
normalised field, ``h = R(q) m̂`` its tilt-compensated direction in the world frame and the reference
field ``(0, √(h_x² + h_y²), h_z)``,

    v_m = R(q)ᵀ (0, √(h_x² + h_y²), h_z) / ‖·‖,   e = â × v + m̂ × v_m

and the same bias and attitude update with the same ``k_P``, ``k_I`` as the IMU form (as ``ahrs``). The
reference field puts magnetic north on the world *y* axis, so this earth frame is already ENU (no frame
conversion, unlike :mod:`riann_ros.estimators.madgwick`). Samples without a field (non-finite or
all-zero ``mag`` row) get the IMU step; the initialisation takes the heading from the field of the
initialising sample when it has one (:func:`~riann_ros.estimators.common.initial_attitude_marg`: the
horizontal part of the tilt-compensated field along +y), and so does a change of the online magnetometer
calibration that the heading disagrees with (:mod:`~riann_ros.magcal.changes`).
:meth:`MahonyEstimator.heading_observed` is True iff the last sample's correction used a field.

Initialisation, per-sample dt, degenerate input and the fast loop (one for both forms: without ``mag`` every sample
takes the IMU step) follow :mod:`riann_ros.estimators.madgwick`: initialised from the first usable accelerometer
sample with :func:`riann_ros.quaternion.from_accelerometer`; a zero accelerometer sample gives a gyro-only step
(bias integral frozen, the current bias still subtracted; ``ahrs`` integrates the raw gyro there, and skips samples
whose gyro is exactly zero); the output is always a finite unit quaternion; :meth:`update` runs the same loop as
:meth:`update_batch` with one sample.
"""

from __future__ import annotations

import math

import numpy as np

from riann_ros.estimators.base import Array, ParamSpec
from riann_ros.estimators.bias import FrontEndSlot, front_end_params
from riann_ros.estimators.classical import Batch, ClassicalFilter
from riann_ros.estimators.common import BIAS_KEY, Quat, Rows, as_array, bias_text, initialise, realigned
from riann_ros.magcal.input import MAG_CAL_PARAMS
from riann_ros.rotations import Vec

#: ahrs 0.4.0 ``Mahony`` defaults (``k_P=1.0``, ``k_I=0.3``).
DEFAULT_KP = 1.0
DEFAULT_KI = 0.3


def _mahony_loop(q: Quat, b: Vec, used: bool, rows: Rows, kp: float, ki: float) -> tuple[Quat, Vec, bool, list]:
    """The filter from the state (q, bias) over the samples, the MARG step where a ``mag`` row has a field and the
    IMU step elsewhere. ``used`` is the heading-observed flag before the samples. Returns (new q, new bias,
    whether the last sample's correction used a field, outputs)."""
    out: list = []
    append = out.append
    sqrt = math.sqrt
    inf = math.inf
    qw, qx, qy, qz = q
    bx, by, bz = b
    for (ax, ay, az), (gx, gy, gz), m, h in zip(rows.acc, rows.gyr, rows.mag, rows.dt, strict=True):
        used = False
        an = sqrt(ax * ax + ay * ay + az * az)
        if an > 0.0:
            ax, ay, az = ax / an, ay / an, az / an
            # expected direction of "up" in the sensor frame v = R(q)ᵀ e_z, error e = â × v
            vx, vy, vz = 2.0 * (qx * qz - qw * qy), 2.0 * (qw * qx + qy * qz), 1.0 - 2.0 * (qx * qx + qy * qy)
            ex, ey, ez = ay * vz - az * vy, az * vx - ax * vz, ax * vy - ay * vx
            if m is not None and 0.0 < (mn := m[0] * m[0] + m[1] * m[1] + m[2] * m[2]) < inf:
                mn = sqrt(mn)
                mx, my, mz = m[0] / mn, m[1] / mn, m[2] / mn
                # reference field (0, ry, rz) from h = R(q) m̂ (as riann_ros.rotations.rotate), seen in the sensor
                # frame: v_m = R(q)ᵀ (0, ry, rz), error e += m̂ × v_m / ‖v_m‖
                tx, ty, tz = 2.0 * (qy * mz - qz * my), 2.0 * (qz * mx - qx * mz), 2.0 * (qx * my - qy * mx)
                hx, hy = mx + qw * tx + (qy * tz - qz * ty), my + qw * ty + (qz * tx - qx * tz)
                ry, rz = sqrt(hx * hx + hy * hy), mz + qw * tz + (qx * ty - qy * tx)
                wx = 2.0 * ry * (qx * qy + qw * qz) + 2.0 * rz * (qx * qz - qw * qy)
                wy = ry * (1.0 - 2.0 * (qx * qx + qz * qz)) + 2.0 * rz * (qw * qx + qy * qz)
                wz = 2.0 * ry * (qy * qz - qw * qx) + rz * (1.0 - 2.0 * (qx * qx + qy * qy))
                wn = sqrt(wx * wx + wy * wy + wz * wz)
                if 0.0 < wn < inf:
                    used = True
                    wx, wy, wz = wx / wn, wy / wn, wz / wn
                    ex, ey, ez = ex + (my * wz - mz * wy), ey + (mz * wx - mx * wz), ez + (mx * wy - my * wx)
            kih = ki * h
            bx, by, bz = bx - kih * ex, by - kih * ey, bz - kih * ez
            gx, gy, gz = gx - bx + kp * ex, gy - by + kp * ey, gz - bz + kp * ez
        else:
            gx, gy, gz = gx - bx, gy - by, gz - bz
        # q ← normalise(q + ½ q ⊗ [0, Ω] dt), the previous q where that is not finite
        hh = 0.5 * h
        nw, nx = qw + (-qx * gx - qy * gy - qz * gz) * hh, qx + (qw * gx + qy * gz - qz * gy) * hh
        ny, nz = qy + (qw * gy - qx * gz + qz * gx) * hh, qz + (qw * gz + qx * gy - qy * gx) * hh
        nn = sqrt(nw * nw + nx * nx + ny * ny + nz * nz)
        if 0.0 < nn < inf:
            qw, qx = nw / nn, nx / nn
            qy, qz = ny / nn, nz / nn
        append((qw, qx, qy, qz))
    if not (math.isfinite(bx) and math.isfinite(by) and math.isfinite(bz)):
        bx = by = bz = 0.0
    return (qw, qx, qy, qz), (bx, by, bz), used, out


class MahonyEstimator(ClassicalFilter):
    """Mahony IMU filter with proportional gain ``kp`` and integral (gyro-bias) gain ``ki``."""

    name = "mahony"
    PARAMS = (
        ParamSpec(
            "kp",
            DEFAULT_KP,
            "Proportional gain k_P (rad/s per unit error): weight of the accelerometer correction. Default 1.0 "
            "= the ahrs 0.4.0 default; the BROAD authors' tuned 9D value is 0.74.",
            min=0.0,
            max=100.0,
            runtime=True,
        ),
        ParamSpec(
            "ki",
            DEFAULT_KI,
            "Integral gain k_I (rad/s² per unit error) of the gyro-bias estimate; 0 disables bias estimation "
            "(the current estimate is then kept). Default 0.3 = the ahrs 0.4.0 default; the BROAD authors' "
            "tuned 9D value is 0.0012.",
            min=0.0,
            max=10.0,
            runtime=True,
        ),
        *MAG_CAL_PARAMS,
        *front_end_params(False, "the filter (its own integral term then tracks what is left)"),
    )

    def _reset_filter(self) -> None:
        self._q: Quat | None = None
        self._b: Vec = (0.0, 0.0, 0.0)
        self._observed = False
        self._fe = FrontEndSlot(self.params)

    @property
    def bias(self) -> Array:
        """Current gyro-bias estimate (rad/s, sensor frame): the front end's plus the integral term's."""
        return np.array(self._b) + np.array(self._fe.bias)

    def diagnostics(self) -> dict[str, str]:
        return {BIAS_KEY: bias_text(self.bias)}

    def heading_observed(self) -> bool:
        return self._observed

    def _debiased(self, acc: Array, gyr: Array, dt: Array) -> Array:
        return self._fe.debias(acc, gyr, dt)

    def _run(self, batch: Batch) -> Array:
        al, gl, hl = batch.as_lists()
        rows = Rows(al, gl, batch.mag if batch.mag is not None else [None] * len(al), hl, batch.realign)
        out: list = []
        q, used = self._q, self._observed
        if q is None:
            q, rows, used = initialise(rows, out)
        if q is not None:
            kp, ki = float(self.params["kp"]), float(self.params["ki"])
            for piece, sd in rows.pieces():
                if sd is not None:  # the calibration changed
                    q = realigned(q, piece.mag[0], sd)
                q, self._b, used, filtered = _mahony_loop(q, self._b, used, piece, kp, ki)
                out += filtered
            self._q = q
        self._observed = used
        return as_array(out)
