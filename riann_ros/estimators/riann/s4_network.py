"""Stage 4, the network: the published RIANN GRU over the rows, as an ensemble of rotated copies (ROS-free).

Model I/O (the official ``riann.onnx`` of the ``riann`` package, Apache-2.0): ``input`` float32 [1, T, 7] = acc
xyz (m/s²), gyr xyz (rad/s), dt (s); ``h0`` [2, 1, 1, 200]; outputs ``output`` [1, T, 4] (unit quaternion w, x,
y, z) and ``hn``. Each copy of the ensemble (:mod:`.s4a_ensemble`) sees the rows in its own rotated frame; their
gravity directions are combined into one attitude per row.

After a hole a fresh state starts at the row after the hole (a *fork*, placed by the grid) and runs beside the
old one for ``restart_warmup`` (at least one row), then replaces it (a *join*): the old state trusts what it
integrated and would keep the hole's error for seconds. docs/riann.md, stage 4.
"""

from __future__ import annotations

import importlib.resources
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import onnxruntime as ort

from riann_ros.estimators.base import Array
from riann_ros.estimators.riann.s4a_ensemble import FLOAT_ROWS, combine, frames, rotate_rows
from riann_ros.estimators.riann.stage import Cause

HIDDEN_SHAPE = (2, 1, 1, 200)
BATCH_CHUNK = 200_000  # network rows per ONNX Runtime call


def default_model_path() -> Path:
    """The official weights shipped in the ``riann`` package."""
    return Path(str(importlib.resources.files("riann") / "riann.onnx"))


def make_session(model_path: str | Path | None = None, threads: int = 1) -> ort.InferenceSession:
    """An ONNX Runtime CPU session for the RIANN model (checks its inputs and outputs)."""
    path = Path(model_path) if model_path else default_model_path()
    if not path.is_file():
        raise FileNotFoundError(f"RIANN model not found: {path}")
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = threads
    opts.inter_op_num_threads = 1
    opts.log_severity_level = 3
    session = ort.InferenceSession(str(path), sess_options=opts, providers=["CPUExecutionProvider"])
    names_in = {i.name for i in session.get_inputs()}
    names_out = {o.name for o in session.get_outputs()}
    if not {"input", "h0"} <= names_in or not {"output", "hn"} <= names_out:
        raise ValueError(
            f"{path} is not a RIANN-compatible model: inputs {sorted(names_in)}, outputs {sorted(names_out)}"
        )
    return session


class Network:
    """Stage 4 (see the module docstring)."""

    NAME = "network"

    def __init__(self, session: ort.InferenceSession, copies: int, warmup: float) -> None:
        self.session = session
        self.rots = frames(copies)
        self.warmup = warmup  # s a fresh state runs beside the old one before it takes over
        self.rows = 0  # rows run since the estimator's reset (compute per sample = rows / samples)
        self.holes = 0  # fresh states started after holes
        self._fresh()

    def _fresh(self) -> None:
        self._h = self._zero()
        self._h_cand: np.ndarray | None = None  # the fresh state after a hole
        self._warm = 0  # rows the fresh state still runs before it takes over

    def _zero(self) -> np.ndarray:
        return np.zeros((len(self.rots), *HIDDEN_SHAPE), dtype=np.float32)

    def restart(self, cause: Cause) -> None:
        self._fresh()
        if cause is Cause.RESET:
            self.rows = self.holes = 0

    def run(self, rows: Sequence[Sequence[float]], forks: list[tuple[int, float]]) -> Array:
        """The ensemble attitude (M, 4) of each row; ``forks``: (row position, grid step) where a fresh state starts
        (before that row; position M: after the last)."""
        m = len(rows)
        out = np.empty((m, 4))
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
                self._h_cand = self._zero()
                self._warm = max(1, math.ceil(self.warmup / forks[f][1]))
                self.holes += 1
                f += 1
                continue
            if pos >= m:
                return out

    def _segment(self, rows: Sequence[Sequence[float]], a: int, b: int, out: Array) -> None:
        for c in range(a, b, BATCH_CHUNK):
            part = rows[c : min(c + BATCH_CHUNK, b)]
            out[c : c + len(part)], self._h = self._net(part, self._h)
            if self._h_cand is not None:
                _, self._h_cand = self._net(part, self._h_cand)

    def _net(self, rows: Sequence[Sequence[float]], h: np.ndarray) -> tuple[Array, np.ndarray]:
        """Rows through every copy (:mod:`.s4a_ensemble`): the combined attitudes, the next states."""
        x = np.asarray(rows, dtype=np.float64).reshape(-1, 7)
        hn = np.empty_like(h)
        outs = []
        for k, r in enumerate(self.rots):
            xk = x if k == 0 else rotate_rows(x, r)
            out, hn[k] = self.session.run(["output", "hn"], {"input": xk.astype(np.float32)[None], "h0": h[k]})
            outs.append(out[0].astype(np.float64))
        if len(outs) == 1 or len(x) > FLOAT_ROWS:
            outs = [q / np.linalg.norm(q, axis=-1, keepdims=True) for q in outs]
        return combine(outs, self.rots), hn

    def diagnostics(self) -> dict[str, str]:
        return {"network copies": str(len(self.rots)), "network restarts after holes": str(self.holes)}
