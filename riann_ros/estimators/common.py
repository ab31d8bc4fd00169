"""Helpers shared by the classical filters (Madgwick, Mahony, VQF), ROS-free.

Input sanitising (the documented degenerate-input rules), the accelerometer initialisation of
Madgwick and Mahony (and, with a magnetometer, the heading from the field), their realign event
(:func:`realigned`), and the batch for their plain-float loops (:class:`Rows`, cut at the realign events by
:func:`cut_at`). The skeleton that runs them is :mod:`.classical`.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from riann_ros import quaternion as quat
from riann_ros.estimators.base import Array
from riann_ros.magcal.changes import Realign, field_disagrees
from riann_ros.magcal.heading import field_heading
from riann_ros.rotations import Quat, Vec

BIAS_KEY = "gyro bias estimate (deg/s)"


def bias_text(bias_rad_s: ArrayLike) -> str:
    """A gyro-bias estimate (rad/s) as diagnostics text in °/s."""
    return ", ".join(f"{v:.3f}" for v in np.degrees(np.asarray(bias_rad_s, dtype=float)))


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


def initial_attitude(ax: float, ay: float, az: float) -> Quat | None:
    """Zero-heading attitude from one accelerometer sample, or None when it carries no direction."""
    if not (ax * ax + ay * ay + az * az > 0.0):
        return None
    w, x, y, z = quat.from_accelerometer([ax, ay, az]).tolist()
    return w, x, y, z


def sanitize_mag(mag: ArrayLike, n: int) -> list:
    """The magnetic field as an ``(N, 3)`` nested list of Python floats; non-finite rows → zeros.

    A zero row means "no field for this sample" (the loops then run their 6D step), so a NaN row and an
    all-zero row are handled alike.
    """
    m = np.array(mag, dtype=float, copy=True).reshape(-1, 3)
    if m.shape != (n, 3):
        raise ValueError(f"mag must have one row per sample, got {m.shape} for {n} samples")
    m[~np.isfinite(m).all(axis=1)] = 0.0
    return m.tolist()


def has_field(mx: float, my: float, mz: float) -> bool:
    """True when a (sanitised) magnetometer sample carries a direction: non-zero and of finite norm."""
    return 0.0 < mx * mx + my * my + mz * mz < math.inf


def initial_attitude_marg(ax: float, ay: float, az: float, mx: float, my: float, mz: float) -> Quat | None:
    """Sensor → ENU attitude from one accelerometer and one magnetometer sample, or None (no usable acc).

    The zero-heading attitude of :func:`initial_attitude`, then :func:`align_heading` to the field. Without a field
    (zero, non-finite, or vertical) the heading stays zero, as in :func:`initial_attitude`.
    """
    q = initial_attitude(ax, ay, az)
    if q is None or not has_field(mx, my, mz):
        return q
    return align_heading(q, (mx, my, mz))


def align_heading(q: Quat, m: Vec) -> Quat:
    """The attitude ``q`` (sensor → ENU) turned about world z so that the horizontal part of the tilt-compensated
    field ``R(q) m`` lies on +y (magnetic north); ``q`` itself when that part is zero or not finite. The tilt is
    kept: only the heading comes from the field."""
    psi = field_heading(q, m)
    if psi is None:
        return q
    w, x, y, z = q
    c = math.cos(0.5 * psi)
    s = math.sin(0.5 * psi)
    # rot_z(psi) ⊗ q
    rw, rx, ry, rz = c * w - s * z, c * x - s * y, c * y + s * x, c * z + s * w
    n = math.sqrt(rw * rw + rx * rx + ry * ry + rz * rz)
    return rw / n, rx / n, ry / n, rz / n


class Rows(NamedTuple):
    """One batch as the plain-float loops take it: nested lists of Python floats, degenerate values neutralised
    (:func:`sanitize_arrays`, :func:`sanitize_mag`); a ``mag`` row that is None or zeros has no field. ``realign``:
    the rows where the online calibration changed the calibration the field gets (the magnetometer front end's
    :class:`~riann_ros.magcal.changes.Realign` events): before each the filter's heading is set anew from the row's
    field if the two disagree (:func:`realigned`)."""

    acc: list
    gyr: list
    mag: list
    dt: list
    realign: tuple[Realign, ...] = ()

    def tail(self, i: int) -> Rows:
        """The samples from index ``i`` on."""
        return self.part(i, len(self.acc))

    def part(self, a: int, b: int) -> Rows:
        """The samples ``a`` to ``b − 1``."""
        return Rows(self.acc[a:b], self.gyr[a:b], self.mag[a:b], self.dt[a:b],
                    tuple(Realign(e.row - a, e.sd_rad) for e in self.realign if a <= e.row < b))

    def pieces(self) -> Iterator[tuple[Rows, float | None]]:
        """The batch cut before each :attr:`realign` row (:func:`cut_at`): each piece, and the calibration's heading
        σ at its first row when the heading is to be checked there (else None)."""
        if not self.realign:  # the common case: the batch as it is, not copied
            yield self, None
            return
        for a, b, sd in cut_at(self.realign, len(self.acc)):
            yield self.part(a, b), sd


def cut_at(realign: tuple[Realign, ...], n: int) -> Iterator[tuple[int, int, float | None]]:
    """``n`` rows cut before each realign row (:attr:`Rows.realign`): ``(start, end, σ)`` per non-empty piece,
    ``σ`` the calibration's heading σ at its first row when the heading is to be checked there, else None."""
    sds = {e.row: e.sd_rad for e in realign}
    for a, b in itertools.pairwise([0, *(k for k in sds if k > 0), n]):
        if b > a:
            yield a, b, sds.get(a)


def realigned(q: Quat, m: Vec, sd_rad: float) -> Quat:
    """The realign event of Madgwick and Mahony: ``q`` (sensor → ENU) with its heading set anew from the field ``m``
    (:func:`align_heading`) if the two disagree (:func:`~riann_ros.magcal.changes.field_disagrees`), else ``q``."""
    return align_heading(q, m) if field_disagrees(q, m, sd_rad) else q


def initialise(rows: Rows, out: list) -> tuple[Quat | None, Rows, bool]:
    """Until the first usable accelerometer sample sets the attitude (its heading from the sample's field, if it has
    one), output the identity; the outputs of the samples consumed are appended to ``out``.

    Returns the attitude (None when no sample was usable), the samples left to filter, and whether the attitude
    was set from a sample with a field (its heading then comes from the field).
    """
    acc, mag = rows.acc, rows.mag
    q: Quat | None = None
    i = 0
    while q is None and i < len(acc):
        q = initial_attitude(*acc[i]) if mag[i] is None else initial_attitude_marg(*acc[i], *mag[i])
        out.append(q if q is not None else (1.0, 0.0, 0.0, 0.0))
        i += 1
    return q, rows.tail(i), q is not None and mag[i - 1] is not None and has_field(*mag[i - 1])


def as_array(rows: list) -> Array:
    """(N, 4) array from a list of 4-tuples (also for N = 0)."""
    return np.array(rows, dtype=float).reshape(-1, 4)
