"""Stage 4, the network: the published RIANN GRU over the rows, as an ensemble of rotated copies (ROS-free).

Model I/O (the official ``riann.onnx`` of the ``riann`` package, Apache-2.0): ``input`` float32 [1, T, 7] = acc
xyz (m/s²), gyr xyz (rad/s), dt (s); ``h0`` [2, 1, 1, 200]; outputs ``output`` [1, T, 4] (unit quaternion w, x,
y, z) and ``hn``. Each copy of the ensemble (:mod:`.s4a_ensemble`) sees the rows in its own rotated frame, all
copies in one call (:mod:`.s4b_model`); their gravity directions are combined into one attitude per row, and how
far they spread goes out with it (an input of stage 8's uncertainty, never of the attitude).

After a hole the grid marks a *fork*: the first row after the hole sample's rows. The *fork row* is output by the
old state, which has integrated the bridge, while a fresh state starts on the same row; from the next row on the
fresh state alone runs (the old one trusts what it integrated and would keep the hole's error for seconds). A fork
after a block's last row makes the next block's first row the fork row. docs/riann.md, stage 4.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from riann_ros.estimators.base import Array
from riann_ros.estimators.riann.s4a_ensemble import MAX_COPIES, combine, combine_floats, copy_rows, frames
from riann_ros.estimators.riann.s4b_model import F32, BatchedModel
from riann_ros.estimators.riann.stage import SMALL_BLOCK, Cause, NetworkBlock, NetworkIn

__all__ = ["MAX_COPIES", "Network"]


class Network:
    """Stage 4 (see the module docstring); ``model`` runs the copies (its ``copies`` is the ensemble's size)."""

    NAME = "network"

    def __init__(self, model: BatchedModel) -> None:
        self.model = model
        self.rots = frames(model.copies)
        self._rows_for = copy_rows(self.rots)
        self.restart(Cause.RESET)

    def restart(self, cause: Cause) -> None:
        """GAP: a fresh state; RESET: also the counts anew."""
        self._h = self.model.fresh_state()
        self._forked = False  # a fork after the last block's last row: the next row is the fork row
        if cause is Cause.RESET:
            self.rows = 0  # rows run since the estimator's reset (compute per sample = rows / samples)
            self.holes = 0  # fresh states started after holes

    def run(self, block: NetworkIn) -> NetworkBlock:
        """The ensemble attitude of each row and the copies' spread; a fresh state from each fork on."""
        rows = block.bias.rows
        m = len(rows)
        q = np.empty((m, 4))
        spread = np.empty(m)
        self.rows += m
        self.holes += len(block.grid.forks)
        forks = sorted({0, *block.grid.forks} if self._forked else set(block.grid.forks))
        pos = 0
        for f in forks:
            if f == m:  # after the last row: the next block starts with the fork row
                break
            if f > pos:
                self._h = self._segment(rows, pos, f, q, spread, self._h)
            x = self._copies(rows, f, f + 1)
            self._net(x, self._h, q, spread, f)  # the fork row: the old state's output ...
            _, self._h = self.model.run(x, self.model.fresh_state())  # ... and a fresh state's start
            pos = f + 1
        self._forked = bool(forks) and forks[-1] == m
        if m > pos:
            self._h = self._segment(rows, pos, m, q, spread, self._h)
        return NetworkBlock(q, spread)

    def _copies(self, rows: Sequence[Sequence[float]], a: int, b: int) -> F32:
        """Rows ``a:b`` as every copy sees them (copies, b − a, 7)."""
        return self._rows_for(np.asarray(rows[a:b], dtype=np.float64).reshape(-1, 7))

    def _segment(self, rows: Sequence[Sequence[float]], a: int, b: int, q: Array, spread: Array, h: F32) -> F32:
        """Rows ``a:b`` through the copies from state ``h`` in one call; the state after them."""
        return self._net(self._copies(rows, a, b), h, q, spread, a)

    def _net(self, x: F32, h: F32, q: Array, spread: Array, a: int) -> F32:
        """The copies' rows (copies, M, 7) through the model from state ``h``: the combined attitudes and their spread
        into ``q`` and ``spread`` from row ``a`` on; returns the next state."""
        out, hn = self.model.run(x, h)
        outs = [o.astype(np.float64) for o in out]
        b = a + x.shape[1]
        if len(outs) > 1 and x.shape[1] <= SMALL_BLOCK:  # the node's path (a row or two per message)
            q[a:b], spread[a:b] = combine_floats(outs, self.rots)
        else:
            q[a:b], spread[a:b] = combine([o / np.linalg.norm(o, axis=-1, keepdims=True) for o in outs], self.rots)
        return hn

    def diagnostics(self) -> dict[str, str]:
        return {"network copies": str(len(self.rots)), "network restarts after holes": str(self.holes)}
