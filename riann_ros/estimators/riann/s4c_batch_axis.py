"""Stage 4c, the batch axis: the published model's declared shapes given a symbolic batch, edited in the protobuf
wire format (ROS-free).

The published RIANN graph (``riann.onnx`` of the ``riann`` package) declares a fixed batch of one (``input``
[1, T, 7], ``h0`` [2, 1, 1, 200]; ``output`` [1, T, 4], ``hn``), though its operators all take a batch.
:func:`batch_model` turns that axis of the four declared shapes (``input``/``output`` axis 0, ``h0``/``hn`` axis 2,
:data:`BATCH_AXES`) into the symbol :data:`BATCH` by rewriting those four ``ValueInfoProto`` messages: every other
byte, the weights included, is copied unchanged, so no ``onnx`` package and no derived file are needed, and any
RIANN-compatible ``model_path`` gets the same treatment. The wire format is the one of
https://protobuf.dev/programming-guides/encoding/, read and written just far enough for that edit; the field
numbers are onnx.proto's (stable across ONNX versions). :mod:`.s4b_model` loads the result and checks it against
the published model.
"""

from __future__ import annotations

from collections.abc import Callable

BATCH = "batch"  # name of the symbolic batch dimension in the edited model
# axis of the batch in each declared shape of the published model
BATCH_AXES = {"input": 0, "h0": 2, "output": 0, "hn": 2}

# field numbers of onnx.proto
MODEL_GRAPH, GRAPH_INPUT, GRAPH_OUTPUT = 7, 11, 12
VALUE_TYPE, TYPE_TENSOR, TENSOR_SHAPE, SHAPE_DIM, DIM_PARAM = 2, 1, 2, 1, 2


def varint(buf: bytes, i: int) -> tuple[int, int]:
    """The varint at ``buf[i:]`` and the position after it."""
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


def fields(msg: bytes) -> list[tuple[int, int, bytes]]:
    """The fields of a message in order: (field number, wire type, payload bytes)."""
    out = []
    i = 0
    while i < len(msg):
        key, i = varint(msg, i)
        wire = key & 7
        if wire == 0:
            j = varint(msg, i)[1]
        elif wire == 2:
            n, i = varint(msg, i)
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


def map_field(msg: bytes, number: int, fn: Callable[[bytes], bytes], which: int | None = None) -> bytes:
    """``msg`` with ``fn`` applied to the payload of the length-delimited field ``number`` (every occurrence, or
    only the ``which``-th)."""
    out = bytearray()
    k = 0
    for n, wire, payload in fields(msg):
        if n == number and wire == 2:
            if which is None or k == which:
                payload = fn(payload)
            k += 1
        out += _field(n, wire, payload)
    return bytes(out)


def _name(value_info: bytes) -> str:
    return next((p.decode() for n, w, p in fields(value_info) if n == 1 and w == 2), "")


def _batch_dim(value_info: bytes) -> bytes:
    """A ``ValueInfoProto`` with its batch axis made the symbol ``batch`` (names not in BATCH_AXES: unchanged)."""
    axis = BATCH_AXES.get(_name(value_info))
    if axis is None:
        return value_info
    dim = _field(DIM_PARAM, 2, BATCH.encode())

    def shape(s: bytes) -> bytes:
        return map_field(s, SHAPE_DIM, lambda _: dim, which=axis)

    return map_field(value_info, VALUE_TYPE,
                     lambda t: map_field(t, TYPE_TENSOR, lambda tt: map_field(tt, TENSOR_SHAPE, shape)))


def batch_model(model: bytes) -> bytes:
    """The serialised ONNX model ``model`` with a symbolic batch axis in the declared shapes of ``input``, ``h0``,
    ``output`` and ``hn`` (:data:`BATCH_AXES`); every other byte (the graph, the weights) is kept as it is."""

    def graph(g: bytes) -> bytes:
        return map_field(map_field(g, GRAPH_INPUT, _batch_dim), GRAPH_OUTPUT, _batch_dim)

    return map_field(model, MODEL_GRAPH, graph)
