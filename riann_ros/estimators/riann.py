"""RIANN: the published recurrent network (2 GRU layers × 200 units) run with ONNX Runtime.

Model I/O (the official ``riann.onnx`` of the ``riann`` package, Apache-2.0):
``input`` float32 [1, T, 7] = acc xyz (m/s²), gyr xyz (rad/s), dt (s); ``h0`` [2, 1, 1, 200];
outputs ``output`` [1, T, 4] (unit quaternion w, x, y, z) and ``hn``.

The network was trained for time steps of 2–20 ms (50–500 Hz) and degrades outside that range
(measured on BROAD: 1000 Hz fed straight in gives 10–25° RMSE). This estimator therefore adapts the
rate causally, one output per input sample, before the samples reach the network:

* **dt < 2 ms (faster than 500 Hz)** — causal block average: samples are accumulated until they span
  at least ``BLOCK_DT`` = 5 ms, then the network takes one step with their time-weighted mean acc and
  gyr and the summed dt (1000 Hz → blocks of 5 → 200 Hz). For the samples inside a block the output
  is the last network output rotated on by the gyroscope integral since then, so there is no hold
  latency; the network's own correction arrives at most ``BLOCK_DT`` later.
* **dt > 20 ms (slower than 50 Hz)** — causal up-sampling (the paper's just-in-time resampling,
  made causal): the interval since the previous sample is split into ``ceil(dt / SUB_DT)`` steps
  (``SUB_DT`` = 10 ms, 100 Hz) with acc and gyr interpolated linearly between the previous and the
  current sample; the output is the network's state after the last sub-step. No latency is added
  (only past and present samples are used); compute grows with the number of sub-steps.
* otherwise the sample goes straight in.

``update`` and ``update_batch`` share the same planning code; the batch call runs the network once
over all planned rows, so both give the same numbers (within float32 round-off).
"""

from __future__ import annotations

import importlib.resources
import math
from pathlib import Path

import numpy as np
import onnxruntime as ort
from numpy.typing import ArrayLike

from riann_ros import quaternion as quat
from riann_ros.estimators.base import Array, AttitudeEstimator, ParamSpec

DT_MIN = 0.002  # s, 500 Hz: fastest rate the network was trained for
DT_MAX = 0.020  # s, 50 Hz: slowest
BLOCK_DT = 0.005  # s, block length for fast inputs (→ 200 Hz)
SUB_DT = 0.010  # s, sub-step for slow inputs (→ 100 Hz)
HIDDEN_SHAPE = (2, 1, 1, 200)
BATCH_CHUNK = 200_000  # network rows per ONNX Runtime call in batch mode


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


class RiannEstimator(AttitudeEstimator):
    """RIANN with its GRU hidden state carried between calls."""

    name = "riann"
    PARAMS = (
        ParamSpec(
            "model_path",
            "",
            "Path of a RIANN-compatible ONNX file; empty = the official weights of the riann package.",
        ),
        ParamSpec(
            "rate_adaptation",
            True,
            "Adapt input rates outside the trained 50-500 Hz causally (block average above 500 Hz, "
            "interpolated sub-steps below 50 Hz). Off: every sample goes straight into the network.",
        ),
    )

    def __init__(self, session: ort.InferenceSession | None = None, **params: object) -> None:
        super().__init__(**params)
        self._session = session or make_session(self.params["model_path"] or None)
        self.reset()

    # -- state ----------------------------------------------------------------------------------
    def reset(self) -> None:
        self._h = np.zeros(HIDDEN_SHAPE, dtype=np.float32)
        self._q_net: Array | None = None  # last network output
        self._prev: tuple[Array, Array] | None = None  # previous raw sample (acc, gyr)
        self._clear_block()

    def _clear_block(self) -> None:
        self._blk_dt = 0.0
        self._blk_acc = np.zeros(3)
        self._blk_gyr = np.zeros(3)
        self._blk_rot = quat.IDENTITY.copy()

    # -- planning: which network rows each input sample produces ----------------------------------
    def _plan_sample(self, a: Array, g: Array, dt: float, rows: list[np.ndarray]) -> tuple[int, Array]:
        """Append the network rows for one sample; return (row index or -1, rotation after it).

        The sample's output is ``net_output[row] ⊗ rotation`` where ``row`` indexes this call's
        rows, or the last network output of an earlier call when -1.
        """
        adapt = self.params["rate_adaptation"]
        first = self._q_net is None and not rows
        if not adapt:
            rows.append(np.concatenate([a, g, [dt]]))
            return len(rows) - 1, quat.IDENTITY
        if dt < DT_MIN and not first:
            # accumulate into the current block (time-weighted mean)
            self._blk_dt += dt
            self._blk_acc += a * dt
            self._blk_gyr += g * dt
            self._blk_rot = quat.multiply(self._blk_rot, quat.from_rotvec(g * dt))
            if self._blk_dt + 1e-12 >= BLOCK_DT:
                rows.append(
                    np.concatenate([self._blk_acc / self._blk_dt, self._blk_gyr / self._blk_dt, [self._blk_dt]])
                )
                self._clear_block()
                return len(rows) - 1, quat.IDENTITY
            return (len(rows) - 1 if rows else -1), self._blk_rot
        if self._blk_dt > 0.0:
            # a pending block followed by a slower sample: close the block with this sample in it
            self._blk_dt += dt
            self._blk_acc += a * dt
            self._blk_gyr += g * dt
            rows.append(np.concatenate([self._blk_acc / self._blk_dt, self._blk_gyr / self._blk_dt, [self._blk_dt]]))
            self._clear_block()
            return len(rows) - 1, quat.IDENTITY
        if dt > DT_MAX:
            n = math.ceil(dt / SUB_DT)
            a0, g0 = self._prev if self._prev is not None else (a, g)
            for k in range(1, n + 1):
                s = k / n
                rows.append(np.concatenate([a0 + s * (a - a0), g0 + s * (g - g0), [dt / n]]))
            return len(rows) - 1, quat.IDENTITY
        rows.append(np.concatenate([a, g, [min(max(dt, DT_MIN), DT_MAX)]]))
        return len(rows) - 1, quat.IDENTITY

    def _run(self, rows: list[np.ndarray] | np.ndarray) -> Array:
        """Run the network over ``rows`` (M, 7) from the current hidden state; return (M, 4)."""
        x = np.asarray(rows, dtype=np.float32).reshape(1, -1, 7)
        out, self._h = self._session.run(["output", "hn"], {"input": x, "h0": self._h})
        q = out[0].astype(np.float64)
        return q / np.linalg.norm(q, axis=-1, keepdims=True)

    def _compose(self, net: Array, idx: np.ndarray, rot: Array) -> Array:
        """Outputs from network rows ``net``, per-sample row indices and rotations."""
        base = np.empty((len(idx), 4))
        has = idx >= 0
        base[has] = net[idx[has]]
        if (~has).any():
            if self._q_net is None:  # cannot happen: the first sample always makes a row
                raise RuntimeError("no network output yet")
            base[~has] = self._q_net
        out = quat.normalize(quat.multiply(base, rot))
        if len(net):
            self._q_net = net[-1]
        return out

    # -- public API -----------------------------------------------------------------------------
    def update(self, acc: ArrayLike, gyr: ArrayLike, dt: float) -> Array:
        a = np.asarray(acc, dtype=float)
        g = np.asarray(gyr, dtype=float)
        rows: list[np.ndarray] = []
        idx, rot = self._plan_sample(a, g, float(dt), rows)
        self._prev = (a, g)
        net = self._run(rows) if rows else np.empty((0, 4))
        return self._compose(net, np.array([idx]), rot[None, :])[0]

    def update_batch(self, acc: ArrayLike, gyr: ArrayLike, dt: ArrayLike) -> Array:
        acc = np.asarray(acc, dtype=float)
        gyr = np.asarray(gyr, dtype=float)
        dt = np.broadcast_to(np.asarray(dt, dtype=float), (len(acc),)).copy()
        n = len(acc)
        if n == 0:
            return np.empty((0, 4))
        in_range = (dt >= DT_MIN) & (dt <= DT_MAX)
        if not self.params["rate_adaptation"] or (bool(in_range.all()) and self._blk_dt == 0.0):
            rows = np.column_stack([acc, gyr, dt])
            idx = np.arange(n)
            rot = np.broadcast_to(quat.IDENTITY, (n, 4))
        else:
            row_list: list[np.ndarray] = []
            idx = np.empty(n, dtype=np.int64)
            rot = np.empty((n, 4))
            for i in range(n):
                idx[i], rot[i] = self._plan_sample(acc[i], gyr[i], float(dt[i]), row_list)
                self._prev = (acc[i], gyr[i])
            rows = np.asarray(row_list).reshape(-1, 7)
        self._prev = (acc[-1], gyr[-1])
        chunks = [self._run(rows[i : i + BATCH_CHUNK]) for i in range(0, len(rows), BATCH_CHUNK)]
        net = np.concatenate(chunks) if chunks else np.empty((0, 4))
        return self._compose(net, idx, rot)
