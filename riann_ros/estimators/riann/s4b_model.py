"""Stage 4b, the model: the published RIANN network with its copies in one ONNX Runtime call (ROS-free).

The ensemble (:mod:`.s4a_ensemble`) runs ``copies`` instances of the same network on differently rotated
inputs. The published graph (``riann.onnx`` of the ``riann`` package) declares a fixed batch of one
(``input`` [1, T, 7], ``h0`` [2, 1, 1, 200]; ``output`` [1, T, 4], ``hn``), so the copies would be
``copies`` separate runs. Its operators (normalise, two ONNX ``GRU`` layers, a 1×1 ``Conv``,
normalise) all take a batch, only the declared shapes do not. :class:`BatchedModel` therefore loads the
model twice:

* the file as published (the reference, and the path whenever the batched one cannot be used);
* the same bytes with the batch axis of the four declared shapes turned from 1 into a symbol
  (:func:`~.s4c_batch_axis.batch_model`: an edit of the protobuf bytes that keeps every other byte).

At load, a probe sequence run through both (every copy a different input and state) must agree within
:data:`PROBE_TOL`, else the batched model is not used (``BatchedModel.reason`` says why) and every call runs
the copies one by one. With the published model and ONNX Runtime 1.31 the two agree exactly (bit for bit:
``test/test_riann_s4b_model.py``, ``bench/bench_network.py``).

A long call runs in equal chunks of at most :data:`CHUNK` rows (the state carried across), which bounds
the memory ONNX Runtime's GRU takes for its input projections (rows × copies × 600 floats per layer).
The chunks are kept long on purpose: ONNX Runtime 1.31's output layer (the 1×1 ``Conv``) rounds
differently in calls of up to 64 rows than in longer ones (the published model's outputs differ by up to
1.3e-6 between one call of 2000 rows and calls of 64; its states do not differ), and a chunk of thousands of
rows gives what one call of the whole gives.
"""

from __future__ import annotations

import importlib.resources
import itertools
from pathlib import Path

import numpy as np
import onnxruntime as ort
from numpy.typing import NDArray

from riann_ros.constants import GRAVITY
from riann_ros.estimators.riann.s4c_batch_axis import BATCH_AXES, batch_model
from riann_ros.estimators.riann.stage import SMALL_BLOCK

F32 = NDArray[np.float32]

CHUNK = 4096  # at most this many rows per ONNX Runtime call (equal chunks, the state carried between them)
PROBE_TOL = 1e-6  # the batched model must agree with the published one this closely on the probe
PROBE_ROWS = 16


def default_model_path() -> Path:
    """The official weights shipped in the ``riann`` package."""
    return Path(str(importlib.resources.files("riann") / "riann.onnx"))


def _options(threads: int) -> ort.SessionOptions:
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = threads
    opts.inter_op_num_threads = 1
    opts.log_severity_level = 3
    return opts


def _session(model: str | bytes, threads: int) -> ort.InferenceSession:
    return ort.InferenceSession(model, sess_options=_options(threads), providers=["CPUExecutionProvider"])


def open_model(model_path: str | Path | None = None, threads: int = 1) -> tuple[Path, ort.InferenceSession]:
    """The model file and an ONNX Runtime CPU session of it, checked to be RIANN-compatible (inputs
    ``input``, ``h0``; outputs ``output``, ``hn``)."""
    path = Path(model_path) if model_path else default_model_path()
    if not path.is_file():
        raise FileNotFoundError(f"RIANN model not found: {path}")
    try:
        session = _session(str(path), threads)
    except Exception as e:  # ONNX Runtime raises its own exception types for unreadable models
        raise ValueError(f"{path} is not a loadable ONNX model: {e}") from e
    names_in = {i.name for i in session.get_inputs()}
    names_out = {o.name for o in session.get_outputs()}
    if not {"input", "h0"} <= names_in or not {"output", "hn"} <= names_out:
        raise ValueError(
            f"{path} is not a RIANN-compatible model: inputs {sorted(names_in)}, outputs {sorted(names_out)}"
        )
    return path, session


def _state_shape(session: ort.InferenceSession) -> tuple[int, ...]:
    """The state of one copy: the declared shape of h0, a symbolic axis (a batch) taken as 1."""
    shape = next(i.shape for i in session.get_inputs() if i.name == "h0")
    return tuple(d if isinstance(d, int) else 1 for d in shape)


def _batchable(session: ort.InferenceSession) -> str:
    """Why the declared shapes do not fit the batch edit ('' = they do)."""
    shapes = {v.name: v.shape for v in (*session.get_inputs(), *session.get_outputs())}
    if len(session.get_inputs()) != 2 or len(shapes) != 4:
        return f"inputs and outputs other than input, h0, output, hn: {sorted(shapes)}"
    for name, axis in BATCH_AXES.items():
        s = shapes[name]
        if len(s) <= axis or not (s[axis] == 1 or isinstance(s[axis], str)):
            return f"{name} has shape {s}, not a batch of 1 (or symbolic) on axis {axis}"
    if len(shapes["h0"]) != 4 or len(shapes["hn"]) != 4:
        return f"h0 {shapes['h0']} / hn {shapes['hn']}: expected 4 axes (layers, directions, batch, units)"
    return ""


def probe(copies: int, rows: int, seed: int = 0) -> F32:
    """Deterministic input rows (copies, rows, 7) like an IMU's: gravity plus noise, gyro, a 5 ms step."""
    rng = np.random.default_rng(seed)
    x = rng.normal(0.0, 1.0, (copies, rows, 7))
    x[..., 2] += GRAVITY
    x[..., 6] = 0.005
    return x.astype(np.float32)


class _Bound:
    """Inputs and outputs of one-call runs of ``rows`` rows, preallocated and bound once (ONNX Runtime I/O
    binding): a call copies the rows and states in, runs, and copies the outputs out."""

    def __init__(self, session: ort.InferenceSession, copies: int, rows: int, state: tuple[int, ...]) -> None:
        self.x = np.zeros((copies, rows, 7), np.float32)
        self.h0 = np.zeros((state[0], state[1], copies, state[3]), np.float32)
        self.out = np.zeros((copies, rows, 4), np.float32)
        self.hn = np.zeros_like(self.h0)
        self.binding = session.io_binding()
        self.binding.bind_cpu_input("input", self.x)
        self.binding.bind_cpu_input("h0", self.h0)
        for name, a in (("output", self.out), ("hn", self.hn)):
            self.binding.bind_output(name, "cpu", 0, np.float32, list(a.shape), a.ctypes.data)


class BatchedModel:
    """``copies`` instances of the RIANN network, run together: :meth:`run` means the same as running the
    published session once per copy (:meth:`run_per_copy`), in one ONNX Runtime call when the batched model
    passed its load-time probe (``batched``; else ``reason`` says why not). One copy runs the published model.

    Not thread-safe (preallocated buffers): one BatchedModel per thread."""

    def __init__(self, model_path: str | Path | None = None, copies: int = 4, threads: int = 1) -> None:
        if copies < 1:
            raise ValueError(f"copies must be at least 1, got {copies}")
        self.path, self.session = open_model(model_path, threads)
        self.copies = copies
        self.state_shape = _state_shape(self.session)
        self._bound: dict[int, _Bound] = {}
        self._one: ort.InferenceSession | None = None  # the session that runs every copy in one call
        if copies == 1:
            self._one, self.reason = self.session, ""
        else:
            self.reason = self._load_batched(threads)

    @property
    def batched(self) -> bool:
        """Every copy runs in one call (the batched model passed its probe, or there is one copy)."""
        return self._one is not None

    def _load_batched(self, threads: int) -> str:
        """Load the batched model and check it against the published one on a probe; returns '' or why not."""
        why = _batchable(self.session)
        if why:
            return why
        try:
            self._one = _session(batch_model(self.path.read_bytes()), threads)
        except Exception as e:  # a graph that does not take a batch fails to load here
            return f"the model with a batch axis does not load: {e}"
        rng = np.random.default_rng(1)
        h = rng.uniform(-0.9, 0.9, (self.copies, *self.state_shape)).astype(np.float32)
        err = 0.0
        try:
            for rows in (1, PROBE_ROWS):  # the bound path and the plain one
                x = probe(self.copies, rows)
                got, want = self.run(x, h), self.run_per_copy(x, h)
                err = max(err, *(float(np.abs(g - w).max()) for g, w in zip(got, want, strict=True)))
        except Exception as e:  # a graph that does not take a batch may fail only when run
            self._one = None
            return f"the model with a batch axis does not run: {e}"
        finally:
            self._bound.clear()
        if not err <= PROBE_TOL:
            self._one = None
            return f"the model with a batch axis differs from the published one by {err:.3g} on the probe"
        return ""

    def fresh_state(self) -> F32:
        """A zero hidden state per copy: (copies, *h0 shape), (copies, 2, 1, 1, 200) for the published model."""
        return np.zeros((self.copies, *self.state_shape), np.float32)

    def _check(self, x: np.ndarray, h: np.ndarray) -> tuple[F32, F32]:
        if x.ndim != 3 or x.shape[0] != self.copies or x.shape[2] != 7:
            raise ValueError(f"input rows must have shape ({self.copies}, T, 7), got {x.shape}")
        if h.shape != (self.copies, *self.state_shape):
            raise ValueError(f"state must have shape {(self.copies, *self.state_shape)}, got {h.shape}")
        return np.ascontiguousarray(x, dtype=np.float32), np.asarray(h, dtype=np.float32)

    def run(self, x: np.ndarray, h: np.ndarray) -> tuple[F32, F32]:
        """Rows ``x`` (copies, T, 7) from states ``h`` (copies, *h0 shape) → outputs (copies, T, 4), next states
        (new arrays: the arguments are not changed)."""
        x, h = self._check(x, h)
        rows = x.shape[1]
        if self._one is None or rows == 0:
            return self.run_per_copy(x, h)
        if rows <= SMALL_BLOCK:  # the node's path: preallocated, bound buffers
            return self._run_bound(x, h)
        out = np.empty((self.copies, rows, 4), np.float32)
        cuts = np.linspace(0, rows, -(-rows // CHUNK) + 1).round().astype(int).tolist()  # equal chunks ≤ CHUNK
        for a, b in itertools.pairwise(cuts):
            out[:, a:b], h = self._run_one(x[:, a:b], h)
        return out, h

    def _to_batch(self, h: F32) -> F32:
        """States (copies, L, D, 1, H) → the batched model's h0 (L, D, copies, H)."""
        s = self.state_shape
        return h.reshape(self.copies, s[0], s[1], s[3]).transpose(1, 2, 0, 3)

    def _from_batch(self, hn: F32) -> F32:
        """The batched model's hn → states (copies, L, D, 1, H), always a new array (never a view of a bound one)."""
        return np.array(hn.transpose(2, 0, 1, 3), dtype=np.float32, order="C").reshape(self.copies, *self.state_shape)

    def _run_bound(self, x: F32, h: F32) -> tuple[F32, F32]:
        assert self._one is not None
        b = self._bound.get(x.shape[1])
        if b is None:
            b = self._bound[x.shape[1]] = _Bound(self._one, self.copies, x.shape[1], self.state_shape)
        b.x[...] = x
        np.copyto(b.h0, self._to_batch(h))
        self._one.run_with_iobinding(b.binding)
        return b.out.copy(), self._from_batch(b.hn)

    def _run_one(self, x: F32, h: F32) -> tuple[F32, F32]:
        assert self._one is not None
        feed = {"input": np.ascontiguousarray(x), "h0": np.ascontiguousarray(self._to_batch(h))}
        out, hn = self._one.run(["output", "hn"], feed)
        return out, self._from_batch(hn)

    def run_per_copy(self, x: np.ndarray, h: np.ndarray) -> tuple[F32, F32]:
        """:meth:`run` as the published session once per copy (the reference)."""
        x, h = self._check(x, h)
        out = np.empty((self.copies, x.shape[1], 4), np.float32)
        hn = h.copy()
        if x.shape[1] == 0:
            return out, hn
        for m in range(self.copies):
            o, hn[m] = self.session.run(["output", "hn"], {"input": x[m : m + 1], "h0": h[m]})
            out[m] = o[0]
        return out, hn
