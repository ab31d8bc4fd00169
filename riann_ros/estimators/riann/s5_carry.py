"""Stage 5, carry to the stamp: each sample's attitude is the newest network output, moved on by the gyro to the
sample's own stamp (ROS-free).

The network's newest output sits at a grid point at or before the sample; the bias-corrected gyro (stage 3's
estimate before the sample's rows) rotates it on to the sample's stamp, so the output has no added latency. The
same stage turns each sample's gyro step (from the previous sample, with the bias before its rows) into the
increment the hand-over and the heading stages follow. docs/riann.md, stage 5.

Blocks of up to :data:`SCALAR_MAX` samples (the node's) run in plain floats, longer ones vectorised; the two
give the same numbers (test_riann_stages).
"""

from __future__ import annotations

import math

import numpy as np

from riann_ros import quaternion as quat
from riann_ros.estimators.base import Array
from riann_ros.estimators.riann.stage import Cause, GridBlock, Quat, Vec
from riann_ros.rotations import IDENTITY, from_rotvec, qmul

SCALAR_MAX = 4


class Carry:
    """Stage 5 (see the module docstring)."""

    NAME = "carry"

    def __init__(self) -> None:
        self.q_net: Quat | None = None  # the newest network output

    def restart(self, cause: Cause) -> None:
        self.q_net = None

    def run(self, net: Array, g: GridBlock, bias: list[Vec]) -> tuple[list[Quat], list[Quat]]:
        """Per sample: the network attitude carried to its stamp (unit), and its bias-corrected gyro increment."""
        if len(g.r0) <= SCALAR_MAX:
            return self._scalar(net, g, bias)
        return self._vector(net, g, bias)

    def _scalar(self, net: Array, g: GridBlock, bias: list[Vec]) -> tuple[list[Quat], list[Quat]]:
        qc, delta = [], []
        for i, (r0, r1) in enumerate(zip(g.r0, g.r1, strict=True)):
            if r1 > r0:
                self.q_net = tuple(net[r1 - 1].tolist())
            q = self.q_net
            if q is None:  # cannot happen: the first sample always makes a row
                raise RuntimeError("no network output yet")
            s = g.s_carry[i]
            if s != 0.0:
                gc, b = g.g_carry[i], bias[r0]
                q = qmul(q, from_rotvec((gc[0] - b[0]) * s, (gc[1] - b[1]) * s, (gc[2] - b[2]) * s))
            w, x, y, z = q
            n = math.sqrt(w * w + x * x + y * y + z * z)
            qc.append((w / n, x / n, y / n, z / n))
            delta.append(_increment(g.g_delta[i], g.s_delta[i], bias[r0]))
        return qc, delta

    def _vector(self, net: Array, g: GridBlock, bias: list[Vec]) -> tuple[list[Quat], list[Quat]]:
        r0 = np.asarray(g.r0)
        r1 = np.asarray(g.r1)
        n = len(r0)
        has = r1 > r0
        base = np.empty((n, 4))
        base[has] = net[r1[has] - 1]
        if (~has).any():  # forward-fill from the last sample with rows (or the previous block's output)
            pos = np.maximum.accumulate(np.where(has, np.arange(n), -1))
            if (pos < 0).any():
                if self.q_net is None:
                    raise RuntimeError("no network output yet")
                base[pos < 0] = self.q_net
            base[pos >= 0] = base[pos[pos >= 0]]
        if has.any():
            self.q_net = tuple(base[np.flatnonzero(has)[-1]].tolist())
        b = np.asarray(bias)
        s = np.asarray(g.s_carry)
        rot = np.tile(np.asarray(IDENTITY), (n, 1))
        move = s != 0.0
        rot[move] = quat.from_rotvec((np.asarray(g.g_carry)[move] - b[r0[move]]) * s[move, None])
        qc = quat.normalize(quat.multiply(base, rot))
        sd = np.asarray(g.s_delta)
        delta = np.tile(np.asarray(IDENTITY), (n, 1))
        step = sd != 0.0
        delta[step] = quat.from_rotvec((np.asarray(g.g_delta)[step] - b[r0[step]]) * sd[step, None])
        return list(map(tuple, qc.tolist())), list(map(tuple, delta.tolist()))

    def diagnostics(self) -> dict[str, str]:
        return {}


def _increment(g: Vec, s: float, b: Vec) -> Quat:
    """The rotation by the gyro ``g`` (rad/s) less the bias ``b`` over ``s`` seconds (identity for 0 s)."""
    if s == 0.0:
        return IDENTITY
    return from_rotvec((g[0] - b[0]) * s, (g[1] - b[1]) * s, (g[2] - b[2]) * s)
