"""A run's kept results as data, not code (ROS-free): the ``.npz`` files of ``OUT/shards`` (:mod:`.store`).

A shard is a NumPy ``.npz`` archive (a zip of ``.npy`` arrays) holding

- ``doc``: UTF-8 JSON — the header (format, what the file holds, whose input it is) and the value, in which every
  dataclass is ``{"$dc": NAME, "f": {field: value}}`` (NAME one of :data:`KNOWN`: nothing else is ever built),
  every tuple ``{"$tuple": [...]}``, every mapping whose keys are not plain strings ``{"$map": [[key, value], ...]}``
  and every array ``{"$arr": "aN"}``;
- ``a0``, ``a1``, …: the arrays, numbers, booleans or text only.

Reading is :func:`decode`: ``numpy.load(allow_pickle=False)`` (an object array, which would need pickle, is refused),
the JSON parsed, each dataclass built from the fields it declares only, and every field checked against its type
hints (:func:`check`). Anything else — a pickle, a damaged file, a file of another format — is a :class:`ShardError`
naming the file; no code in a shard is ever run.
"""

from __future__ import annotations

import io
import json
import types
import typing
import zipfile
from dataclasses import fields, is_dataclass
from pathlib import Path
from typing import Any

import numpy as np

from riann_ros.evaluation.results import ResultRow, RunStats, SequenceResult
from riann_ros.evaluation.scoring import Score
from riann_ros.evaluation.specs import EstimatorSpec

#: the dataclasses a shard may hold, by name: a name not here is an invalid shard
KNOWN: dict[str, type] = {c.__name__: c for c in (SequenceResult, ResultRow, Score, RunStats, EstimatorSpec)}
ARRAY_KINDS = "biufcU"  # bool, int, unsigned, float, complex, text: what loads without pickle
_TAGS = ("$dc", "$tuple", "$map", "$arr")


class ShardError(ValueError):
    """A shard that cannot be read back as what it claims to hold (message: which file, what is wrong)."""


class _Encoder:
    def __init__(self) -> None:
        self.arrays: dict[str, np.ndarray] = {}

    def value(self, obj: Any) -> Any:
        if is_dataclass(obj) and not isinstance(obj, type):
            name = type(obj).__name__
            if KNOWN.get(name) is not type(obj):
                raise TypeError(f"a shard cannot hold a {type(obj).__qualname__}")
            return {"$dc": name, "f": {f.name: self.value(getattr(obj, f.name)) for f in fields(obj)}}
        if isinstance(obj, np.ndarray):
            return self.array(obj)
        if isinstance(obj, np.generic):
            return obj.item()
        if isinstance(obj, tuple | list | dict):
            return self.container(obj)
        if obj is None or isinstance(obj, bool | int | float | str):
            return obj
        raise TypeError(f"a shard cannot hold a {type(obj).__qualname__}")

    def array(self, a: np.ndarray) -> dict[str, str]:
        if a.dtype.kind not in ARRAY_KINDS:
            raise TypeError(f"a shard cannot hold an array of {a.dtype}")
        key = f"a{len(self.arrays)}"
        self.arrays[key] = np.ascontiguousarray(a)
        return {"$arr": key}

    def container(self, obj: tuple | list | dict) -> Any:
        if isinstance(obj, tuple):
            return {"$tuple": [self.value(v) for v in obj]}
        if isinstance(obj, list):
            return [self.value(v) for v in obj]
        if all(isinstance(k, str) and not k.startswith("$") for k in obj):
            return {k: self.value(v) for k, v in obj.items()}
        return {"$map": [[self.value(k), self.value(v)] for k, v in obj.items()]}


def encode(header: dict[str, Any], value: Any) -> bytes:
    """The ``.npz`` bytes of ``value`` under ``header`` (plain JSON values); TypeError for what a shard cannot hold
    (another class, an object array)."""
    enc = _Encoder()
    doc = {**header, "value": enc.value(value)}
    text = json.dumps(doc, separators=(",", ":"), allow_nan=True).encode()
    buf = io.BytesIO()
    save: Any = np.savez  # its stubs take a keyword argument for a flag
    save(buf, doc=np.frombuffer(text, dtype=np.uint8), **enc.arrays)
    return buf.getvalue()


class _Decoder:
    def __init__(self, arrays: Any, where: str) -> None:
        self.arrays = arrays
        self.where = where

    def fail(self, what: str) -> ShardError:
        return ShardError(f"{self.where}: {what}")

    def value(self, obj: Any) -> Any:
        if isinstance(obj, list):
            return [self.value(v) for v in obj]
        if not isinstance(obj, dict):
            return obj
        tag = next((t for t in _TAGS if t in obj), None)
        if tag is None:
            return {k: self.value(v) for k, v in obj.items()}
        if len(obj) != (2 if tag == "$dc" else 1):
            raise self.fail(f"malformed {tag} entry")
        body = obj[tag]
        if tag == "$arr":
            if not isinstance(body, str) or not body.startswith("a") or body not in self.arrays.files:
                raise self.fail(f"no array {body!r}")
            return self.arrays[body]
        if tag == "$tuple" and isinstance(body, list):
            return tuple(self.value(v) for v in body)
        if tag == "$map" and isinstance(body, list) and all(isinstance(p, list) and len(p) == 2 for p in body):
            return {_hashable(self.value(k)): self.value(v) for k, v in body}
        if tag == "$dc":
            return self.dataclass(body, obj.get("f"))
        raise self.fail(f"malformed {tag} entry")

    def dataclass(self, name: Any, values: Any) -> Any:
        cls = KNOWN.get(name) if isinstance(name, str) else None
        if cls is None or not isinstance(values, dict):
            raise self.fail(f"holds an unknown record {name!r}")
        declared = {f.name for f in fields(cls) if f.init}
        unknown = set(values) - declared
        if unknown:
            raise self.fail(f"{name} has no field {sorted(unknown)[0]!r}")
        try:
            obj = cls(**{k: self.value(v) for k, v in values.items()})
        except (TypeError, ValueError) as exc:
            raise self.fail(f"{name}: {exc}") from None
        check(obj, self.where)
        return obj


def _hashable(key: Any) -> Any:
    if isinstance(key, list | dict | np.ndarray):
        raise TypeError("unhashable key")
    return key


def _open(data: bytes, where: str) -> np.lib.npyio.NpzFile:
    """The arrays of a shard's bytes, never unpickled (ShardError for anything but an ``.npz`` archive)."""
    try:
        arrays = np.load(io.BytesIO(data), allow_pickle=False)
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise ShardError(f"{where}: cannot be read as a shard ({type(exc).__name__}: {exc})") from None
    if not isinstance(arrays, np.lib.npyio.NpzFile):
        raise ShardError(f"{where}: not a shard (a single array, no archive)")
    return arrays


def _doc(arrays: np.lib.npyio.NpzFile, where: str) -> dict[str, Any]:
    """The JSON document of a shard's arrays."""
    if "doc" not in arrays.files:
        raise ShardError(f"{where}: not a shard (no doc)")
    raw = arrays["doc"]
    if raw.dtype != np.uint8 or raw.ndim != 1:
        raise ShardError(f"{where}: not a shard (doc is not text)")
    doc = json.loads(raw.tobytes().decode())
    if not isinstance(doc, dict) or "value" not in doc:
        raise ShardError(f"{where}: not a shard (no value)")
    return doc


_READ_ERRORS = (OSError, ValueError, EOFError, zipfile.BadZipFile, KeyError, TypeError, UnicodeDecodeError)


def decode(data: bytes, where: str) -> tuple[dict[str, Any], Any]:
    """(header, value) of a shard's bytes (``where``: its path, for messages); :class:`ShardError` for anything that
    is not a valid shard."""
    with _open(data, where) as arrays:
        try:
            doc = _doc(arrays, where)
            value = _Decoder(arrays, where).value(doc.pop("value"))
        except ShardError:
            raise
        except _READ_ERRORS as exc:
            raise ShardError(f"{where}: cannot be read as a shard ({type(exc).__name__}: {exc})") from None
    return doc, value


def read(path: Path) -> tuple[dict[str, Any], Any]:
    """:func:`decode` of a file; FileNotFoundError when there is none."""
    return decode(path.read_bytes(), str(path))


def read_header(path: Path) -> dict[str, Any]:
    """A shard's header only (its value neither built nor checked, its arrays not read); FileNotFoundError when there
    is none, :class:`ShardError` when it is no shard."""
    where = str(path)
    with _open(path.read_bytes(), where) as arrays:
        try:
            doc = _doc(arrays, where)
        except ShardError:
            raise
        except _READ_ERRORS as exc:
            raise ShardError(f"{where}: cannot be read as a shard ({type(exc).__name__}: {exc})") from None
    doc.pop("value")
    return doc


# ---- the type check ------------------------------------------------------------------------------------------------
def _ok(value: Any, hint: Any) -> bool:
    """Whether ``value`` is of the type ``hint`` (the forms the kept records use)."""
    if hint is Any:
        return True
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        return any(_ok(value, a) for a in args)
    if origin in (list, dict, tuple):
        return _ok_container(value, origin, args)
    if hint is type(None):
        return value is None
    if hint in (float, int):  # an int is a float too; a bool is neither
        return isinstance(value, int if hint is int else int | float) and not isinstance(value, bool)
    return isinstance(hint, type) and isinstance(value, hint)


def _ok_container(value: Any, origin: Any, args: tuple[Any, ...]) -> bool:
    if not isinstance(value, origin):
        return False
    if origin is list:
        return all(_ok(v, args[0]) for v in value)
    if origin is dict:
        return all(_ok(k, args[0]) and _ok(v, args[1]) for k, v in value.items())
    if len(args) == 2 and args[1] is Ellipsis:
        return all(_ok(v, args[0]) for v in value)
    return len(args) == len(value) and all(_ok(v, a) for v, a in zip(value, args, strict=True))


_HINTS: dict[type, dict[str, Any]] = {}


def _hints(cls: type) -> dict[str, Any]:
    if cls not in _HINTS:
        _HINTS[cls] = typing.get_type_hints(cls)
    return _HINTS[cls]


def check(obj: Any, where: str) -> None:
    """ShardError unless every field of the dataclass ``obj`` holds a value of its declared type."""
    for name, hint in _hints(type(obj)).items():
        if name in {f.name for f in fields(obj)} and not _ok(getattr(obj, name), hint):
            raise ShardError(f"{where}: {type(obj).__name__}.{name} is not a {_text(hint)}")


def _text(hint: Any) -> str:
    return getattr(hint, "__name__", None) or str(hint).replace("typing.", "")

