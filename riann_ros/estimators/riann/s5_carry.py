"""Stage 5, carry to the stamp: each sample's attitude is the newest network output, moved on by the gyro to the
sample's own stamp (ROS-free).

The network's newest output sits at a grid point at or before the sample; the bias-corrected gyro (stage 3's
estimate before the sample's rows) rotates it on to the sample's stamp, so the output has no added latency. The
same stage turns each sample's gyro step (from the previous sample, with the bias before its rows) into the
increment the hand-over and the heading stages follow. docs/riann.md, stage 5.

Blocks of up to :data:`~.stage.SMALL_BLOCK` samples (the node's) run in plain floats (:meth:`Carry._floats`),
longer ones vectorised (:meth:`Carry._vector`, the reference); a test holds the two equal on random blocks.
"""

from __future__ import annotations

import math

import numpy as np

from riann_ros import quaternion as quat
from riann_ros.estimators.riann.stage import SMALL_BLOCK, CarryBlock, CarryIn, Cause, Quat, Vec
from riann_ros.rotations import IDENTITY, from_rotvec, qmul


class Carry:
    """Stage 5 (see the module docstring)."""

    NAME = "carry"

    def __init__(self) -> None:
        self.restart(Cause.RESET)

    def restart(self, cause: Cause) -> None:
        """GAP and RESET: from the fresh network's first output."""
        self.q_net: Quat | None = None  # the newest network output

    def run(self, block: CarryIn) -> CarryBlock:
        """Per sample: the network attitude carried to its stamp (unit), and its bias-corrected gyro increment."""
        if len(block.grid.r0) <= SMALL_BLOCK:
            return self._floats(block)
        return self._vector(block)

    def _floats(self, block: CarryIn) -> CarryBlock:
        """:meth:`_vector` in plain floats."""
        g, net, bias = block.grid, block.net.q, block.bias.bias_rad_s
        qc: list[Quat] = []
        delta: list[Quat] = []
        for i, (r0, r1) in enumerate(zip(g.r0, g.r1, strict=True)):
            if r1 > r0:
                self.q_net = tuple(net[r1 - 1].tolist())
            q = self.q_net
            if q is None:  # cannot happen: the first sample always makes a row
                raise RuntimeError("no network output yet")
            s = g.carry_s[i]
            if s != 0.0:
                gc, b = g.gyr_carry_rad_s[i], bias[r0]
                q = qmul(q, from_rotvec((gc[0] - b[0]) * s, (gc[1] - b[1]) * s, (gc[2] - b[2]) * s))
            w, x, y, z = q
            n = math.sqrt(w * w + x * x + y * y + z * z)
            qc.append((w / n, x / n, y / n, z / n))
            delta.append(_increment(g.gyr_delta_rad_s[i], g.delta_s[i], bias[r0]))
        return CarryBlock(qc, delta)

    def _vector(self, block: CarryIn) -> CarryBlock:
        """The reference, vectorised over the block."""
        g, net, bias = block.grid, block.net.q, block.bias.bias_rad_s
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
        s = np.asarray(g.carry_s)
        rot = np.tile(np.asarray(IDENTITY), (n, 1))
        move = s != 0.0
        rot[move] = quat.from_rotvec((np.asarray(g.gyr_carry_rad_s)[move] - b[r0[move]]) * s[move, None])
        qc = quat.normalize(quat.multiply(base, rot))
        sd = np.asarray(g.delta_s)
        delta = np.tile(np.asarray(IDENTITY), (n, 1))
        step = sd != 0.0
        delta[step] = quat.from_rotvec((np.asarray(g.gyr_delta_rad_s)[step] - b[r0[step]]) * sd[step, None])
        return CarryBlock([_quat(v) for v in qc.tolist()], [_quat(v) for v in delta.tolist()])

    def diagnostics(self) -> dict[str, str]:
        return {}


def _quat(v: list[float]) -> Quat:
    return v[0], v[1], v[2], v[3]


def _increment(g: Vec, s: float, b: Vec) -> Quat:
    """The rotation by the gyro ``g`` (rad/s) less the bias ``b`` over ``s`` seconds (identity for 0 s)."""
    if s == 0.0:
        return IDENTITY
    return from_rotvec((g[0] - b[0]) * s, (g[1] - b[1]) * s, (g[2] - b[2]) * s)
