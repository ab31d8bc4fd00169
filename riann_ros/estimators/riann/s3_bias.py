"""Stage 3, the gyro bias: VQF's bias estimator on the network's rows, the bias known before each row removed
(ROS-free).

RIANN was trained on gyros without a large bias; a MEMS gyro starts with several °/s. The front end
(:class:`~riann_ros.estimators.bias.GyroBiasFrontEnd`, shared with Madgwick and Mahony) runs on the same rows the
network gets, at the grid step (rebuilt, keeping its estimate, when the grid step switches), and each row's gyro
loses the bias known before it: causal, and the network's output never feeds back. The carry stage (5) uses the
same estimate. With ``rate_adaptation`` off the rows are the samples, at the first sample's step, each scaled by
its own dt. VQF also gives the standard deviation of its estimate (the worst direction); it goes out per row with
the estimate (:class:`~.stage.BiasBlock`) for stage 8's uncertainty and never changes the attitude. docs/riann.md,
stage 3.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from riann_ros.estimators.base import Array
from riann_ros.estimators.bias import GyroBiasFrontEnd
from riann_ros.estimators.common import BIAS_KEY, bias_text
from riann_ros.estimators.riann.stage import ZERO3, BiasBlock, Cause, GridBlock, Row6, Row7, Vec, first_step

BATCH_ROWS = 8  # from this many rows on, VQF takes them in one call (the same numbers as one at a time)


class FrontEnd(GyroBiasFrontEnd):
    """The front end that also keeps VQF's standard deviation of its estimate (rad/s, the worst direction):
    :attr:`sigma` before the next row, and per row of the last batch the value before it."""

    def __init__(self, ts: float, clip: float, sigma_init: float) -> None:
        super().__init__(ts, clip, sigma_init)
        self.sigma = self._sigma_now()
        self.sigma_rows: list[float] = []

    def _sigma_now(self) -> float:
        vqf = self._vqf
        assert vqf is not None
        return float(vqf.getBiasEstimate()[1])

    def update(self, acc: ArrayLike, gyr: ArrayLike, dt: float | None = None) -> None:
        super().update(acc, gyr, dt)
        self.sigma = self._sigma_now()

    def _took_batch(self, out: dict[str, Array]) -> None:
        """Per row of the batch the σ before it (:attr:`sigma_rows`), then the σ after the last."""
        sig = out["biasSigma"]
        self.sigma_rows = [self.sigma, *sig[:-1].tolist()]
        self.sigma = float(sig[-1])


class Bias:
    """Stage 3 (see the module docstring). ``fixed_step``: the rows' steps vary (``rate_adaptation`` off): the
    estimator keeps the first row's step and scales each row's gyro by its own."""

    NAME = "bias"

    def __init__(self, on: bool, clip: float, sigma_init: float, fixed_step: bool = False) -> None:
        self.on, self.clip, self.sigma_init, self.fixed_step = on, clip, sigma_init, fixed_step
        self.restart(Cause.RESET)

    def restart(self, cause: Cause) -> None:
        """RESET: the front end anew at the next row; GAP: kept (the same sensor)."""
        if cause is Cause.RESET:
            self.fe: FrontEnd | None = None

    @property
    def bias(self) -> Vec:
        """The estimate now (rad/s): the bias known before the next row."""
        return self.fe.bias if self.fe is not None else ZERO3

    @property
    def sigma_now(self) -> float:
        """The σ of the estimate now (rad/s): VQF's, or ``bias_sigma_init`` before the first row (0 when off)."""
        if not self.on:
            return 0.0
        return self.fe.sigma if self.fe is not None else math.radians(self.sigma_init)

    def run(self, block: GridBlock) -> BiasBlock:
        """The rows with the bias removed (acc, gyr, dt), and the bias and its σ before each row and after the last."""
        rows, steps = block.rows, block.row_step_s
        before: list[Vec] = []
        sigma: list[float] = []
        if self.on and rows:
            i = 0
            while i < len(rows):  # runs of rows at one step
                j = i + 1
                if not self.fixed_step:
                    while j < len(rows) and steps[j] == steps[i]:
                        j += 1
                else:
                    j = len(rows)
                before += self._run(rows[i:j], steps[i:j], sigma)
                i = j
        else:
            before = [self.bias] * len(rows)
            sigma = [self.sigma_now] * len(rows)
        out: list[Row7] = [(r[0], r[1], r[2], r[3] - b[0], r[4] - b[1], r[5] - b[2], s)
                           for r, b, s in zip(rows, before, steps, strict=True)]
        before.append(self.bias)
        sigma.append(self.sigma_now)
        return BiasBlock(out, before, sigma)

    def _run(self, rows: list[Row6], steps: list[float], sigma: list[float]) -> list[Vec]:
        """Rows at one step (or at any, ``fixed_step``) through the front end; the bias before each (its σ appended
        to ``sigma``)."""
        step = steps[0]
        if self.fe is None:
            self.fe = FrontEnd(first_step(step), self.clip, self.sigma_init)
        elif not self.fixed_step and step != self.fe.ts:
            self.fe.set_ts(step)  # the grid step switched: VQF rebuilt for it, the estimate kept
        fe = self.fe
        if len(rows) < BATCH_ROWS:
            out = []
            for r, s in zip(rows, steps, strict=True):
                out.append(fe.bias)
                sigma.append(fe.sigma)
                fe.update(r[0:3], r[3:6], s)
            return out
        x = np.asarray(rows, dtype=float)
        b = fe.update_batch(x[:, 0:3], x[:, 3:6], np.asarray(steps, dtype=float))
        sigma += fe.sigma_rows
        return [(v[0], v[1], v[2]) for v in b.tolist()]

    def diagnostics(self) -> dict[str, str]:
        return {BIAS_KEY: bias_text(self.fe.bias)} if self.fe is not None else {}
