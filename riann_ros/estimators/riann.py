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
  (``SUB_DT`` = 2.5 ms, 400 Hz) with acc and gyr interpolated linearly between the previous and the
  current sample; the output is the network's state after the last sub-step. No latency is added
  (only past and present samples are used); compute grows with the number of sub-steps (16 network
  steps per sample at 25 Hz). Measured on BROAD 02/07/15 resampled to 25 Hz: sub-steps of 10 / 5 /
  2.5 / 2 ms give 1.52/4.08/1.04°, 1.20/3.23/1.20°, 1.09/2.88/1.34° and 1.22/2.75/1.33° (native rate
  0.63/1.46/0.98°; without adaptation 12.4/20.4/7.5°); repeating the current sample instead of
  interpolating is worse (2.5/8.7/1.4°).
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
SUB_DT = 0.0025  # s, sub-step for slow inputs (→ 400 Hz; chosen on BROAD 02/07/15 at 25 Hz)
HIDDEN_SHAPE = (2, 1, 1, 200)
BATCH_CHUNK = 200_000  # network rows per ONNX Runtime call in batch mode

Quat = tuple[float, float, float, float]
IDENTITY_T: Quat = (1.0, 0.0, 0.0, 0.0)


def _qmul(p: Quat, q: Quat) -> Quat:
    pw, px, py, pz = p
    qw, qx, qy, qz = q
    return (
        pw * qw - px * qx - py * qy - pz * qz,
        pw * qx + px * qw + py * qz - pz * qy,
        pw * qy - px * qz + py * qw + pz * qx,
        pw * qz + px * qy - py * qx + pz * qw,
    )


def _rotvec(x: float, y: float, z: float) -> Quat:
    angle = math.sqrt(x * x + y * y + z * z)
    if angle < 1e-12:
        return (1.0, 0.5 * x, 0.5 * y, 0.5 * z)
    k = math.sin(0.5 * angle) / angle
    return (math.cos(0.5 * angle), x * k, y * k, z * k)


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

    # -- state ----------------------------------------------------------------------------------
    def reset(self) -> None:
        self._h = np.zeros(HIDDEN_SHAPE, dtype=np.float32)
        self._q_net: Array | None = None  # last network output
        self._prev: tuple[float, ...] | None = None  # previous raw sample (ax, ay, az, gx, gy, gz)
        self._clear_block()

    def _clear_block(self) -> None:
        self._blk_dt = 0.0
        self._blk_sum = [0.0] * 6  # time-weighted sums of acc and gyr
        self._blk_rot: Quat = IDENTITY_T

    # -- planning: which network rows each input sample produces ----------------------------------
    # Plain Python floats: this runs once per sample, and numpy's per-call overhead would dominate.
    def _plan_sample(self, x: tuple[float, ...], dt: float, rows: list[tuple[float, ...]]) -> tuple[int, Quat]:
        """Append the network rows for sample ``x`` = (acc xyz, gyr xyz); return (row, rotation).

        The sample's output is ``net_output[row] ⊗ rotation`` where ``row`` indexes this call's
        rows, or the last network output of an earlier call when -1.
        """
        if not self.params["rate_adaptation"]:
            rows.append((*x, dt))
            return len(rows) - 1, IDENTITY_T
        first = self._q_net is None and not rows
        if dt < DT_MIN and not first:
            # accumulate into the current block (time-weighted mean)
            self._blk_dt += dt
            b = self._blk_sum
            for k in range(6):
                b[k] += x[k] * dt
            self._blk_rot = _qmul(self._blk_rot, _rotvec(x[3] * dt, x[4] * dt, x[5] * dt))
            if self._blk_dt + 1e-12 >= BLOCK_DT:
                rows.append(self._close_block())
                return len(rows) - 1, IDENTITY_T
            return (len(rows) - 1 if rows else -1), self._blk_rot
        if self._blk_dt > 0.0:
            # a pending block followed by a slower sample: close the block with this sample in it
            self._blk_dt += dt
            b = self._blk_sum
            for k in range(6):
                b[k] += x[k] * dt
            rows.append(self._close_block())
            return len(rows) - 1, IDENTITY_T
        if dt > DT_MAX:
            n = math.ceil(dt / SUB_DT)
            x0 = self._prev if self._prev is not None else x
            for k in range(1, n + 1):
                s = k / n
                rows.append((*(x0[j] + s * (x[j] - x0[j]) for j in range(6)), dt / n))
            return len(rows) - 1, IDENTITY_T
        rows.append((*x, min(max(dt, DT_MIN), DT_MAX)))
        return len(rows) - 1, IDENTITY_T

    def _close_block(self) -> tuple[float, ...]:
        t = self._blk_dt
        row = (*(v / t for v in self._blk_sum), t)
        self._clear_block()
        return row

    def _run(self, rows: list[tuple[float, ...]] | np.ndarray) -> Array:
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
        # The node's hot path: plain floats (numpy per-call overhead dominates for one sample). Same
        # arithmetic as update_batch's vectorised _compose.
        a0, a1, a2 = acc  # type: ignore[misc, str-unpack]
        g0, g1, g2 = gyr  # type: ignore[misc, str-unpack]
        x = (float(a0), float(a1), float(a2), float(g0), float(g1), float(g2))  # type: ignore[arg-type]
        rows: list[tuple[float, ...]] = []
        _, rot = self._plan_sample(x, float(dt), rows)
        self._prev = x
        if rows:
            self._q_net = self._run(rows)[-1]
        if self._q_net is None:  # cannot happen: the first sample always makes a row
            raise RuntimeError("no network output yet")
        if rot is IDENTITY_T:
            return self._q_net.copy()
        w, x1, y1, z1 = _qmul(tuple(self._q_net.tolist()), rot)
        n = math.sqrt(w * w + x1 * x1 + y1 * y1 + z1 * z1)
        return np.array([w / n, x1 / n, y1 / n, z1 / n])

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
            row_list: list[tuple[float, ...]] = []
            idx_list: list[int] = []
            rot_list: list[Quat] = []
            plan = self._plan_sample
            for x, d in zip(np.column_stack([acc, gyr]).tolist(), dt.tolist(), strict=True):
                i, r = plan(tuple(x), d, row_list)
                self._prev = tuple(x)
                idx_list.append(i)
                rot_list.append(r)
            rows = np.asarray(row_list, dtype=float).reshape(-1, 7)
            idx = np.asarray(idx_list, dtype=np.int64)
            rot = np.asarray(rot_list, dtype=float)
        self._prev = (*(float(v) for v in acc[-1]), *(float(v) for v in gyr[-1]))
        chunks = [self._run(rows[i : i + BATCH_CHUNK]) for i in range(0, len(rows), BATCH_CHUNK)]
        net = np.concatenate(chunks) if chunks else np.empty((0, 4))
        return self._compose(net, idx, rot)
