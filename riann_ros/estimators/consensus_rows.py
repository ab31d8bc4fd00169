"""VQF on RIANN's rows: the consensus's second opinion, on the input RIANN's stages 1–3 made (ROS-free).

RIANN's stages 1–3 turn any stream (jittered, late, 25 Hz or 1 kHz, with holes and a turn-on gyro bias) into rows
on a constant-step grid with the bias estimate removed (:class:`~.riann.stage.BiasBlock`). VQF (Laidig & Seel 2023)
filters exactly those rows: its strapdown integration sees the grid's constant step (VQF is built for one sampling
time), its gyro the bias that stage 3 — VQF's own bias estimator, with a prior fit for a MEMS turn-on bias — learned,
so VQF's own bias estimation is off (it would estimate a residual of an estimate that is already VQF's). Each row's
attitude is carried to the samples' stamps by the gyro as RIANN's network output is (stage 5, the same
:class:`~.riann.s5_carry.Carry` on VQF's rows). Both opinions so share RIANN's input handling and differ in the
attitude kernel only: the network's and VQF's accelerometer low-pass. docs/consensus.md.

Restarts: a hole is bridged by the grid's interpolated rows (VQF integrates them as it would the samples); a gap
(longer than the gate's ``max_dt``) starts VQF's attitude anew from the next row's accelerometer; a reset starts
everything anew.
"""

from __future__ import annotations

import itertools

import numpy as np
from vqf import VQF

from riann_ros.estimators.base import Array
from riann_ros.estimators.riann.s5_carry import Carry
from riann_ros.estimators.riann.stage import (
    SMALL_BLOCK,
    CarryIn,
    Cause,
    NetworkBlock,
    Row7,
    UncertaintyIn,
    first_step,
)

DEFAULT_TAU_ACC = 3.0  # s; VQF's tauAcc default (vqf 2.1.2)


class VqfRows:
    """VQF over the rows of each RIANN call, its attitude carried to every sample's stamp."""

    def __init__(self, tau_acc: float = DEFAULT_TAU_ACC) -> None:
        self.tau_acc = tau_acc
        self.carry = Carry()
        self.restart(Cause.RESET)

    def restart(self, cause: Cause) -> None:
        """RESET and GAP: VQF's attitude starts anew at the next row (the carry too)."""
        self._vqf: VQF | None = None
        self._ts = 0.0
        self.carry.restart(cause)

    def set_tau_acc(self, tau_acc: float) -> None:
        self.tau_acc = tau_acc
        if self._vqf is not None:
            self._vqf.setTauAcc(tau_acc)

    def _filter(self, step: float) -> tuple[VQF, float]:
        if self._vqf is None:
            self._ts = first_step(step)
            self._vqf = VQF(self._ts, tauAcc=self.tau_acc, motionBiasEstEnabled=False, restBiasEstEnabled=False,
                            magDistRejectionEnabled=False)
        return self._vqf, self._ts

    def run(self, u: UncertaintyIn, restarts: list[int]) -> list[tuple[float, float, float, float]]:
        """VQF's attitude (sensor → its 6D earth frame) at each sample of RIANN's last call ``u``; VQF's attitude
        starts anew at each row in ``restarts`` (a hole it is not to bridge)."""
        rows = u.bias.rows
        q = np.empty((len(rows), 4))
        cuts = [0, *sorted(r for r in set(restarts) if 0 < r < len(rows)), len(rows)]
        for a, b in itertools.pairwise(cuts):
            if a in restarts:
                self._vqf = None
            if b > a:
                q[a:b] = self._rows(rows[a:b])
        c = self.carry.run(CarryIn(u.grid, u.bias, NetworkBlock(q, np.zeros(len(rows)))))
        return c.q

    def _rows(self, rows: list[Row7]) -> Array:
        """VQF over rows (acc, gyr less the bias, step): its attitude after each."""
        v, ts = self._filter(rows[0][6])
        if len(rows) < SMALL_BLOCK:
            q = np.empty((len(rows), 4))
            for k, r in enumerate(rows):
                s = r[6] / ts
                v.update(np.array((r[3] * s, r[4] * s, r[5] * s)), np.array((r[0], r[1], r[2])))
                q[k] = v.getQuat6D()
            return q
        x = np.asarray(rows, dtype=float)
        g = np.ascontiguousarray(x[:, 3:6] * (x[:, 6] / ts)[:, None])
        return np.asarray(v.updateBatch(g, np.ascontiguousarray(x[:, 0:3]))["quat6D"])


__all__ = ["DEFAULT_TAU_ACC", "VqfRows"]
