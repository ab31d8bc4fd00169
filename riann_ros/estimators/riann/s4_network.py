"""Stage 4, the network: the published RIANN GRU over the rows, as an ensemble of rotated copies (ROS-free).

Model I/O (the official ``riann.onnx`` of the ``riann`` package, Apache-2.0): ``input`` float32 [1, T, 7] = acc
xyz (m/s²), gyr xyz (rad/s), dt (s); ``h0`` [2, 1, 1, 200]; outputs ``output`` [1, T, 4] (unit quaternion w, x,
y, z) and ``hn``. Each copy of the ensemble (:mod:`.s4a_ensemble`) sees the rows in its own rotated frame, all
copies in one call (:mod:`.s4b_model`); their gravity directions are combined into one attitude per row, and how
far they spread is kept per row (:attr:`Network.spread`, an input of stage 8's uncertainty, never of the attitude).

After a hole a fresh state starts at the row after the hole (a *fork*, placed by the grid) and runs beside the
old one for ``restart_warmup`` (at least one row), then replaces it (a *join*): the old state trusts what it
integrated and would keep the hole's error for seconds. docs/riann.md, stage 4.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from riann_ros.estimators.base import Array
from riann_ros.estimators.riann.s4a_ensemble import FLOAT_ROWS, combine_spread, copy_rows, frames
from riann_ros.estimators.riann.s4b_model import BatchedModel
from riann_ros.estimators.riann.stage import Cause


class Network:
    """Stage 4 (see the module docstring); ``model`` runs the copies (its ``copies`` is the ensemble's size)."""

    NAME = "network"

    def __init__(self, model: BatchedModel, warmup: float) -> None:
        self.model = model
        self.rots = frames(model.copies)
        self._rows_for = copy_rows(self.rots)
        self.warmup = warmup  # s a fresh state runs beside the old one before it takes over
        self.rows = 0  # rows run since the estimator's reset (compute per sample = rows / samples)
        self.holes = 0  # fresh states started after holes
        self.spread = np.zeros(0)  # per row of the last run: the copies' spread around their mean direction (rad)
        self._fresh()

    def _fresh(self) -> None:
        self._h = self.model.fresh_state()
        self._h_cand: np.ndarray | None = None  # the fresh state after a hole
        self._warm = 0  # rows the fresh state still runs before it takes over

    def restart(self, cause: Cause) -> None:
        self._fresh()
        if cause is Cause.RESET:
            self.rows = self.holes = 0

    def run(self, rows: Sequence[Sequence[float]], forks: list[tuple[int, float]]) -> Array:
        """The ensemble attitude (M, 4) of each row; ``forks``: (row position, grid step) where a fresh state starts
        (before that row; position M: after the last)."""
        m = len(rows)
        out = np.empty((m, 4))
        self.spread = np.empty(m)
        self.rows += m
        pos, f = 0, 0
        while True:
            stop = min(forks[f][0] if f < len(forks) else m, pos + self._warm if self._warm > 0 else m)
            if stop > pos:
                self._segment(rows, pos, stop, out)
                if self._warm > 0:
                    self._warm -= stop - pos
                pos = stop
            if self._warm == 0 and self._h_cand is not None:  # join: the fresh state takes over
                self._h, self._h_cand = self._h_cand, None
            if f < len(forks) and forks[f][0] == pos:  # fork: a fresh state starts here
                self._h_cand = self.model.fresh_state()
                self._warm = max(1, math.ceil(self.warmup / forks[f][1]))
                self.holes += 1
                f += 1
                continue
            if pos >= m:
                return out

    def _segment(self, rows: Sequence[Sequence[float]], a: int, b: int, out: Array) -> None:
        x = self._rows_for(np.asarray(rows[a:b], dtype=np.float64).reshape(-1, 7))
        out[a:b], self.spread[a:b], self._h = self._net(x, self._h)
        if self._h_cand is not None:
            _, _, self._h_cand = self._net(x, self._h_cand)

    def _net(self, x: np.ndarray, h: np.ndarray) -> tuple[Array, Array, np.ndarray]:
        """The copies' rows (copies, M, 7) through the model: the combined attitudes, their spread, the next states."""
        q, hn = self.model.run(x, h)
        outs = [o.astype(np.float64) for o in q]
        if len(outs) == 1 or x.shape[1] > FLOAT_ROWS:
            outs = [o / np.linalg.norm(o, axis=-1, keepdims=True) for o in outs]
        att, spread = combine_spread(outs, self.rots)
        return att, spread, hn

    def diagnostics(self) -> dict[str, str]:
        return {"network copies": str(len(self.rots)), "network restarts after holes": str(self.holes)}
