"""World-frame conventions of the node outputs, and roll/pitch/yaw (ROS-free).

The estimators give the orientation of the sensor frame in a z-up world frame, ENU (REP-103):
``v_enu = q_enu ⊗ v_sensor ⊗ q_enu⁻¹`` (see :mod:`riann_ros.quaternion`). A node publishes it in the
world frame ``W`` chosen by its ``world_frame`` parameter as

    q_W = C_W ⊗ q_enu

where ``C_W`` is the fixed rotation taking ENU coordinates to ``W`` coordinates, the physical change of
axes (``v_W = C_W ⊗ v_enu ⊗ C_W⁻¹``):

=========  ======================================  ======================================================
``W``      axes                                    ``C_W``
=========  ======================================  ======================================================
``enu``    x east, y north, z up                   identity
``ned``    x north, y east, z down                 ``v_ned = (v_y, v_x, −v_z)``: 180° about (x + y)/√2
``nwu``    x north, y west, z up                   ``v_nwu = (v_y, −v_x, v_z)``: −90° about z
=========  ======================================  ======================================================

Without a magnetometer the heading is not referenced to north: an estimator's heading 0 means "the
sensor x axis along ENU x", which every frame calls *east*. So the same start-up attitude reads
yaw 0 in ENU, yaw +90° in NED and yaw −90° in NWU (and, for a level sensor whose z axis points up,
roll 180° in NED, whose z axis points down). The physical change was chosen over a rotation that keeps
a 6D heading of 0 at 0 in every frame because the two cannot both hold (a rotation mapping ENU x to
NED x maps east onto north) and a magnetometer (true north) must give the physically right heading
in every frame; docs/node.md explains it for users.

Roll, pitch and yaw are the ZYX (intrinsic yaw–pitch–roll, Tait–Bryan) angles of ``q_W`` in its own
world frame: ``R(q_W) = Rz(yaw) · Ry(pitch) · Rx(roll)``; yaw about the world z axis (counter-clockwise
seen from above in ENU and NWU, clockwise seen from above in NED, whose z points down), pitch in
[−90°, 90°], roll and yaw in (−180°, 180°].

Two flavours of each function: plain-float ones for the node's per-message path (no numpy per sample)
and vectorised ones (``(N, 4)`` arrays) for tests and offline use; they give the same numbers.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from riann_ros import quaternion as quat
from riann_ros.rotations import Quat

ENU = "enu"
NED = "ned"
NWU = "nwu"
WORLD_FRAMES = (ENU, NED, NWU)

_H = math.sqrt(0.5)
#: ``C_W`` as a quaternion ``(w, x, y, z)``: ENU coordinates → ``W`` coordinates.
FROM_ENU: dict[str, tuple[float, float, float, float]] = {
    ENU: (1.0, 0.0, 0.0, 0.0),
    NED: (0.0, _H, _H, 0.0),
    NWU: (_H, 0.0, 0.0, -_H),
}
#: ``C_W`` as a rotation matrix (``v_W = C_W @ v_enu``): the definitions the quaternions are tested against.
FROM_ENU_MATRIX: dict[str, NDArray[np.float64]] = {
    ENU: np.eye(3),
    NED: np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]),
    NWU: np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]),
}



def check_world_frame(name: str) -> str:
    """``name`` if it is a supported world frame, else ``ValueError``."""
    if name not in FROM_ENU:
        raise ValueError(f"world_frame must be one of {', '.join(WORLD_FRAMES)}, got {name!r}")
    return name


def to_world(q_enu: ArrayLike, world_frame: str) -> NDArray[np.float64]:
    """``C_W ⊗ q_enu`` for quaternion(s) ``[w, x, y, z]`` of shape ``(4,)`` or ``(N, 4)``."""
    c = FROM_ENU[check_world_frame(world_frame)]
    q = np.asarray(q_enu, dtype=float)
    if world_frame == ENU:
        return q.copy()
    return quat.multiply(np.array(c), q)


def to_world_scalar(w: float, x: float, y: float, z: float, world_frame: str) -> Quat:
    """:func:`to_world` of one quaternion with plain floats (the node's per-message path)."""
    if world_frame == ENU:
        return w, x, y, z
    cw, cx, cy, cz = FROM_ENU[world_frame]
    return (
        cw * w - cx * x - cy * y - cz * z,
        cw * x + cx * w + cy * z - cz * y,
        cw * y - cx * z + cy * w + cz * x,
        cw * z + cx * y - cy * x + cz * w,
    )


def rpy_deg(q: ArrayLike) -> NDArray[np.float64]:
    """ZYX roll, pitch, yaw (degrees) of quaternion(s) ``[w, x, y, z]``: shape ``(3,)`` or ``(N, 3)``."""
    w, x, y, z = np.moveaxis(np.asarray(q, dtype=float), -1, 0)
    roll = np.arctan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2.0 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return np.degrees(np.stack([roll, pitch, yaw], axis=-1))


def rpy_deg_scalar(w: float, x: float, y: float, z: float) -> tuple[float, float, float]:
    """:func:`rpy_deg` of one quaternion with plain floats."""
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x))))
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return math.degrees(roll), math.degrees(pitch), math.degrees(yaw)


def from_rpy_deg(roll: float, pitch: float, yaw: float) -> NDArray[np.float64]:
    """The quaternion ``[w, x, y, z]`` of ZYX angles (degrees): ``Rz(yaw) · Ry(pitch) · Rx(roll)``."""
    r, p, y = (math.radians(a) for a in (roll, pitch, yaw))
    qz = quat.from_rotvec([0.0, 0.0, y])
    qy = quat.from_rotvec([0.0, p, 0.0])
    qx = quat.from_rotvec([r, 0.0, 0.0])
    return quat.multiply(quat.multiply(qz, qy), qx)
