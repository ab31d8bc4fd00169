"""The RIANN network's copies in one ONNX Runtime call (ROS-free).

The ensemble (:mod:`.ensemble`) runs ``copies`` instances of the same network on differently rotated
inputs. The published graph (``riann.onnx`` of the ``riann`` package) declares a fixed batch of one
(``input`` [1, T, 7], ``h0`` [2, 1, 1, 200]; ``output`` [1, T, 4], ``hn``), so the copies would be
``copies`` separate runs. Its operators (normalise, two ONNX ``GRU`` layers, a 1×1 ``Conv``,
normalise) all take a batch, only the declared shapes do not. :class:`Network` therefore loads the
model twice:

* the file as published (the reference, and the path whenever the batched one cannot be used);
* the same bytes with the batch axis of the four declared shapes (``input``/``output`` axis 0,
  ``h0``/``hn`` axis 2) turned from 1 into the symbol ``batch``. The edit rewrites those four
  ``ValueInfoProto`` messages in the protobuf wire format (:func:`batch_model`): every other byte, the
  weights included, is copied unchanged, so no ``onnx`` package and no derived file are needed, and any
  RIANN-compatible ``model_path`` gets the same treatment.

At load, a probe sequence run through both (every copy a different input and state) must agree within
:data:`PROBE_TOL`, else the batched model is not used (``Network.reason`` says why) and every call runs
the copies one by one, as before. With the published model and ONNX Runtime 1.31 the two agree
exactly (bit for bit: ``test/test_network.py``, ``bench/bench_network.py``).

One call runs up to :data:`CHUNK` rows at a time (the state carried across), which bounds the
memory ONNX Runtime's GRU takes for its input projections (rows × copies × 600 floats per layer).
"""

from __future__ import annotations

import importlib.resources
from collections.abc import Callable
from pathlib import Path

import numpy as np
import onnxruntime as ort
from numpy.typing import NDArray

F32 = NDArray[np.float32]

CHUNK = 4096  # rows per ONNX Runtime call (the state is carried between chunks)
PROBE_TOL = 1e-6  # the batched model must agree with the published one this closely on the probe
PROBE_ROWS = 16
BATCH = "batch"  # name of the symbolic batch dimension in the edited model
# axis of the batch in each declared shape of the published model
BATCH_AXES = {"input": 0, "h0": 2, "output": 0, "hn": 2}


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


# -- protobuf wire format (https://protobuf.dev/programming-guides/encoding/), just enough to edit shapes -------
def _varint(buf: bytes, i: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        c = buf[i]
        i += 1
        value |= (c & 0x7F) << shift
        if c < 0x80:
            return value, i
        shift += 7


def _put_varint(value: int) -> bytes:
    out = bytearray()
    while value >= 0x80:
        out.append(value & 0x7F | 0x80)
        value >>= 7
    out.append(value)
    return bytes(out)


def _fields(msg: bytes) -> list[tuple[int, int, bytes]]:
    """The fields of a message in order: (field number, wire type, payload bytes)."""
    out = []
    i = 0
    while i < len(msg):
        key, i = _varint(msg, i)
        wire = key & 7
        if wire == 0:
            j = _varint(msg, i)[1]
        elif wire == 2:
            n, i = _varint(msg, i)
            j = i + n
        elif wire in (1, 5):
            j = i + (8 if wire == 1 else 4)
        else:
            raise ValueError(f"unsupported protobuf wire type {wire}")
        if j > len(msg):
            raise ValueError("truncated protobuf message")
        out.append((key >> 3, wire, msg[i:j]))
        i = j
    return out


def _field(number: int, wire: int, payload: bytes) -> bytes:
    length = _put_varint(len(payload)) if wire == 2 else b""
    return _put_varint(number << 3 | wire) + length + payload


def _map(msg: bytes, number: int, fn: Callable[[bytes], bytes], which: int | None = None) -> bytes:
    """``msg`` with ``fn`` applied to the payload of the length-delimited field ``number`` (every occurrence, or
    only the ``which``-th)."""
    out = bytearray()
    k = 0
    for n, wire, payload in _fields(msg):
        if n == number and wire == 2:
            if which is None or k == which:
                payload = fn(payload)
            k += 1
        out += _field(n, wire, payload)
    return bytes(out)


def _name(value_info: bytes) -> str:
    return next((p.decode() for n, w, p in _fields(value_info) if n == 1 and w == 2), "")


# field numbers of onnx.proto (stable across ONNX versions)
MODEL_GRAPH, GRAPH_INPUT, GRAPH_OUTPUT = 7, 11, 12
VALUE_TYPE, TYPE_TENSOR, TENSOR_SHAPE, SHAPE_DIM, DIM_PARAM = 2, 1, 2, 1, 2


def _batch_dim(value_info: bytes) -> bytes:
    """A ``ValueInfoProto`` with its batch axis made the symbol ``batch`` (names not in BATCH_AXES: unchanged)."""
    axis = BATCH_AXES.get(_name(value_info))
    if axis is None:
        return value_info
    dim = _field(DIM_PARAM, 2, BATCH.encode())

    def shape(s: bytes) -> bytes:
        return _map(s, SHAPE_DIM, lambda _: dim, which=axis)

    return _map(value_info, VALUE_TYPE, lambda t: _map(t, TYPE_TENSOR, lambda tt: _map(tt, TENSOR_SHAPE, shape)))


def batch_model(model: bytes) -> bytes:
    """The serialised ONNX model ``model`` with a symbolic batch axis in the declared shapes of ``input``, ``h0``,
    ``output`` and ``hn`` (:data:`BATCH_AXES`); every other byte (the graph, the weights) is kept as it is."""

    def graph(g: bytes) -> bytes:
        return _map(_map(g, GRAPH_INPUT, _batch_dim), GRAPH_OUTPUT, _batch_dim)

    return _map(model, MODEL_GRAPH, graph)


# -- the network ------------------------------------------------------------------------------------
def _state_shape(session: ort.InferenceSession) -> tuple[int, ...]:
    shape = next(i.shape for i in session.get_inputs() if i.name == "h0")
    if not all(isinstance(d, int) for d in shape):
        raise ValueError(f"the model's h0 must have a fixed shape, got {shape}")
    return tuple(shape)


def _batchable(session: ort.InferenceSession) -> str:
    """Why the declared shapes do not fit the batch edit ('' = they do)."""
    shapes = {v.name: v.shape for v in (*session.get_inputs(), *session.get_outputs())}
    if len(session.get_inputs()) != 2 or len(shapes) != 4:
        return f"inputs and outputs other than input, h0, output, hn: {sorted(shapes)}"
    for name, axis in BATCH_AXES.items():
        s = shapes[name]
        if len(s) <= axis or s[axis] != 1:
            return f"{name} has shape {s}, not a batch of 1 on axis {axis}"
    if len(shapes["h0"]) != 4 or shapes["hn"] != shapes["h0"]:
        return f"h0 {shapes['h0']} / hn {shapes['hn']}: expected the same 4-axis shape"
    return ""


def probe(copies: int, rows: int, seed: int = 0) -> F32:
    """Deterministic input rows (copies, rows, 7) like an IMU's: gravity plus noise, gyro, a 5 ms step."""
    rng = np.random.default_rng(seed)
    x = rng.normal(0.0, 1.0, (copies, rows, 7))
    x[..., 2] += 9.81
    x[..., 6] = 0.005
    return x.astype(np.float32)


class Network:
    """``copies`` instances of the RIANN network, run together: :meth:`run` means the same as running the
    published session once per copy (``run_per_copy``), in one ONNX Runtime call when the batched model passed
    its load-time probe (``batched``; else ``reason`` says why not).

    Not thread-safe (preallocated buffers): one Network per thread."""

    def __init__(self, model_path: str | Path | None = None, copies: int = 4, threads: int = 1) -> None:
        if copies < 1:
            raise ValueError(f"copies must be at least 1, got {copies}")
        self.path, self.session = open_model(model_path, threads)
        self.copies = copies
        self.state_shape = _state_shape(self.session)
        self.hidden = self.state_shape[-1]
        self._batched: ort.InferenceSession | None = None
        self._binding: ort.IOBinding | None = None
        self._h0 = self._hn = np.zeros(0, np.float32)  # the batched model's h0 and hn
        self.reason = "one copy: the published model" if copies == 1 else self._load_batched(threads)

    @property
    def batched(self) -> bool:
        return self._batched is not None

    def _load_batched(self, threads: int) -> str:
        """Load the batched model and check it against the published one on a probe; returns '' or why not."""
        why = _batchable(self.session)
        if why:
            return why
        try:
            self._batched = _session(batch_model(self.path.read_bytes()), threads)
        except Exception as e:  # a graph that does not take a batch fails to load here
            return f"the model with a batch axis does not load: {e}"
        s = self.state_shape
        self._h0 = np.zeros((s[0], s[1], self.copies, s[3]), np.float32)
        self._hn = np.zeros_like(self._h0)
        x = probe(self.copies, PROBE_ROWS)
        h = np.random.default_rng(1).uniform(-0.9, 0.9, (self.copies, *self.state_shape)).astype(np.float32)
        self._binding = self._batched.io_binding()
        try:
            got = self.run(x, h)
        except Exception as e:  # a graph that does not take a batch may fail only when run
            self._batched = self._binding = None
            return f"the model with a batch axis does not run: {e}"
        want = self.run_per_copy(x, h)
        err = max(float(np.abs(g - w).max()) for g, w in zip(got, want, strict=True))
        if not err <= PROBE_TOL:
            self._batched = self._binding = None
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
        """Rows ``x`` (copies, T, 7) from states ``h`` (copies, *h0 shape) → outputs (copies, T, 4), next states."""
        x, h = self._check(x, h)
        if self._batched is None:
            return self.run_per_copy(x, h)
        out = np.empty((self.copies, x.shape[1], 4), np.float32)
        for start in range(0, x.shape[1], CHUNK):
            h = self._run_batched(x[:, start : start + CHUNK], h, out[:, start : start + CHUNK])
        return out, h.copy() if x.shape[1] == 0 else h

    def _run_batched(self, x: F32, h: F32, out: F32) -> F32:
        """One ONNX Runtime call on the batched model (I/O bound to preallocated buffers); writes ``out``."""
        assert self._batched is not None and self._binding is not None
        s, b = self.state_shape, self._binding
        c = self.copies
        np.copyto(self._h0, h.reshape(c, s[0], s[1], s[3]).transpose(1, 2, 0, 3))
        b.bind_cpu_input("input", np.ascontiguousarray(x))
        b.bind_cpu_input("h0", self._h0)
        direct = out.flags.c_contiguous
        dest = out if direct else np.empty(out.shape, np.float32)
        b.bind_output("output", "cpu", 0, np.float32, list(dest.shape), dest.ctypes.data)
        b.bind_output("hn", "cpu", 0, np.float32, list(self._hn.shape), self._hn.ctypes.data)
        self._batched.run_with_iobinding(b)
        if not direct:
            out[...] = dest
        return np.ascontiguousarray(self._hn.transpose(2, 0, 1, 3)).reshape(c, *s)

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
