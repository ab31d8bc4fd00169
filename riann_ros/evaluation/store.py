"""A run's results kept as they come (ROS-free): ``OUT/shards/``, one file per finished input, so a run stopped at
any point keeps every input it finished, and ``--resume`` evaluates only the others.

- ``OUT/shards/run.json``: what the run was asked (the settings, the tuning specs; :func:`fingerprint`) and the
  format. A resumed run must ask the same: :func:`check` names every setting that differs.
- ``OUT/shards/<key>.npz``: one input's :class:`~riann_ros.evaluation.results.SequenceResult` as data (JSON and
  NumPy arrays, :mod:`~riann_ros.evaluation.shard_codec`; never a pickle: reading a shard runs no code), with the
  input's path, occurrence and identity (:func:`identity`: size, modification time and a hash of the first and last
  64 KiB of each of its files). The key is a hash of the path as given and of how many times it came earlier in the
  input list. A file is written under a temporary name, flushed to disk and then renamed, so it is there whole or
  not at all; a shard is replaced only by a newer result of the same input (a retried failure; the plot series
  moving to an earlier input).
- ``OUT/shards/tuning.npz``: the tuning's results (``--tune``), so a resumed run does not tune again.

A shard is read back with validation: its format, its input and occurrence, every record's fields and their types;
one that fails any check, or whose input has changed since (another identity), counts as not finished and that input
is evaluated again (:func:`stale` names the changed ones).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from collections.abc import Mapping, Sequence
from dataclasses import fields, is_dataclass
from pathlib import Path
from typing import Any

from riann_ros.evaluation import shard_codec
from riann_ros.evaluation.results import EvalSettings, SequenceResult
from riann_ros.evaluation.specs import EstimatorSpec

SHARDS = "shards"
MANIFEST = "run.json"
SUFFIX = ".npz"  # a shard's
TUNING = "tuning" + SUFFIX
LEGACY_SUFFIX = ".pkl"  # the shards of format 1 (pickles): counted, never read
FORMAT = 2
HEAD_TAIL = 1 << 16  # bytes of each end of an input's files hashed into its identity
NEW, REPLACE, RESUME = "new", "replace", "resume"  # an --out folder: a new run, --force, --resume


class RunMismatch(ValueError):
    """The shards in ``--out`` are not this run's (another run's, or a resumed run that asks something else)."""


def _plain(obj: Any) -> Any:
    """JSON-plain form of settings: dataclasses by their fields (every field, whatever the class holds)."""
    if is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: _plain(getattr(obj, f.name)) for f in fields(obj)}
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_plain(v) for v in obj]
    if obj is None or isinstance(obj, bool | int | float | str):
        return obj
    return str(obj)


def fingerprint(settings: EvalSettings, tune: Sequence[str] = (), tune_scenario: str = "") -> dict[str, Any]:
    """What a run asks that decides its results: every evaluation setting, and the tuning specs (not the inputs,
    which a resumed run may extend, nor how many workers)."""
    fp: dict[str, Any] = dict(_plain(settings))
    if tune:
        fp["tune"] = list(tune)
        fp["tune_scenario"] = tune_scenario
    from riann_ros import __version__

    fp["riann_ros"] = __version__
    return json.loads(json.dumps(fp))  # as read back from run.json


def _short(v: Any) -> str:
    text = json.dumps(v, separators=(",", ":"))
    return text if len(text) <= 160 else text[:157] + "..."


def differences(old: dict[str, Any], new: dict[str, Any], labels: Mapping[str, str] | None = None) -> list[str]:
    """Each setting of ``new`` that ``old`` has otherwise, as ``name: OLD in the earlier run, NEW now`` (``labels``:
    what to call a setting, e.g. by its command-line options)."""
    labels = labels or {}
    return [f"{k}{f' ({labels[k]})' if k in labels else ''}: {_short(old.get(k))} in the earlier run, "
            f"{_short(new.get(k))} now" for k in sorted(set(old) | set(new)) if old.get(k) != new.get(k)]


def shard_keys(sources: Sequence[str]) -> list[tuple[int, str]]:
    """Each input's occurrence (an input given twice runs twice) and shard file name."""
    seen: dict[str, int] = {}
    keys = []
    for src in sources:
        k = seen[src] = seen.get(src, -1) + 1
        keys.append((k, hashlib.sha256(f"{k}\0{src}".encode()).hexdigest()[:32] + SUFFIX))
    return keys


def unfinished(out: Path) -> int:
    """How many input results an earlier run left in ``out`` (-1: its shards folder holds no run we know)."""
    d = out / SHARDS
    if not d.is_dir():
        return 0
    n = sum(1 for p in d.iterdir() if p.suffix in (SUFFIX, LEGACY_SUFFIX) and p.stem != "tuning")
    return n if (d / MANIFEST).is_file() else (-1 if n else 0)


def check(out: Path, fp: dict[str, Any], mode: str, labels: Mapping[str, str] | None = None) -> None:
    """Refuse (:class:`RunMismatch`) before any work: a new run into a folder holding an earlier run's shards, or a
    resumed run whose settings differ from the earlier run's (naming each difference; ``labels``: as
    :func:`differences`)."""
    d = out / SHARDS
    if mode == REPLACE or not d.is_dir():
        return
    n = unfinished(out)
    if mode == NEW and n:
        raise RunMismatch(f"{out} holds an earlier run's results of {max(n, 0)} input(s) ({d}): --resume continues "
                          "that run (evaluating only the inputs it has not finished), --force starts over")
    if mode == RESUME:
        try:
            old = json.loads((d / MANIFEST).read_text())
        except (OSError, ValueError) as exc:
            if n == 0:
                return
            raise RunMismatch(f"cannot resume: {d / MANIFEST} is missing or unreadable ({exc}); --force starts "
                              "over") from exc
        if old.get("format") != FORMAT:
            raise RunMismatch(f"cannot resume: {d} was written in shard format {old.get('format')}, this riann_ros "
                              f"reads format {FORMAT}; --force starts over")
        diff = differences(old.get("settings", {}), fp, labels)
        if diff:
            raise RunMismatch("cannot resume: this run asks for other settings than the earlier run in "
                              f"{out} (give the same options, or --force to start over):\n  " + "\n  ".join(diff))


def _write_atomic(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def identity(path: str | os.PathLike[str]) -> dict[str, Any] | None:
    """What tells a changed input from the one a shard was made of: the total size and the latest modification time
    (ns) of its files (a bag directory: every file in it) and a SHA-256 of each file's name, size and first and last
    :data:`HEAD_TAIL` bytes; None when it cannot be read from here."""
    p = Path(path)
    try:
        files = sorted(f for f in p.rglob("*") if f.is_file()) if p.is_dir() else [p]
        h = hashlib.sha256()
        size = mtime = 0
        for f in files:
            st = f.stat()
            size, mtime = size + st.st_size, max(mtime, st.st_mtime_ns)
            h.update(f"{f.relative_to(p) if p.is_dir() else f.name}\0{st.st_size}\0".encode())
            with open(f, "rb") as fh:
                h.update(fh.read(HEAD_TAIL))
                if st.st_size > HEAD_TAIL:
                    fh.seek(max(st.st_size - HEAD_TAIL, HEAD_TAIL))
                    h.update(fh.read(HEAD_TAIL))
    except OSError:
        return None
    return {"size": size, "mtime_ns": mtime, "head_tail_sha256": h.hexdigest()}


def changed(old: Any, new: dict[str, Any] | None) -> str:
    """How an input's identity ``new`` differs from the shard's ``old`` ("" when it does not)."""
    if old == new:
        return ""
    if not isinstance(old, dict) or new is None:
        return "it cannot be compared with the earlier run's (unreadable now, or kept without an identity)"
    what = []
    if old.get("size") != new["size"]:
        what.append(f"size {old.get('size')} → {new['size']} bytes")
    if old.get("mtime_ns") != new["mtime_ns"]:
        what.append("modified since")
    if old.get("head_tail_sha256") != new["head_tail_sha256"]:
        what.append("other content")
    return ", ".join(what) or "another identity"


def stale(out: Path, sources: Sequence[str]) -> list[tuple[str, str]]:
    """(input, how it changed) of every input whose shard in ``out`` was made of another file than the one at its
    path now: a resumed run evaluates those again."""
    d = out / SHARDS
    found = []
    for src, (occurrence, name) in zip(sources, shard_keys(sources), strict=True):
        try:
            head = shard_codec.read_header(d / name)
        except (FileNotFoundError, shard_codec.ShardError):
            continue
        if (head.get("format"), head.get("source"), head.get("occurrence")) == (FORMAT, src, occurrence):
            why = changed(head.get("identity"), identity(src))
            if why:
                found.append((src, why))
    return found


class ShardStore:
    """``OUT/shards`` of one run over ``sources``: opened ``mode`` :data:`NEW` (refused when it holds an earlier run),
    :data:`REPLACE` (an earlier run's shards removed first) or :data:`RESUME` (refused when the settings differ)."""

    def __init__(self, out: Path, fp: dict[str, Any], mode: str, sources: Sequence[str]) -> None:
        check(out, fp, mode)
        self.dir = out / SHARDS
        self.sources = list(sources)
        self.keys = shard_keys(self.sources)
        self.changed: dict[int, str] = {}  # by input index: how an input changed since its shard (load)
        if mode == REPLACE and self.dir.is_dir():
            shutil.rmtree(self.dir)
        self.dir.mkdir(parents=True, exist_ok=True)
        for tmp in self.dir.glob(".*.tmp"):  # a write cut off by a kill
            tmp.unlink(missing_ok=True)
        if not (self.dir / MANIFEST).is_file():
            manifest = {"format": FORMAT, "settings": fp}
            _write_atomic(self.dir / MANIFEST, (json.dumps(manifest, indent=1) + "\n").encode())

    def load(self) -> dict[int, SequenceResult]:
        """The results the shards hold (by input index; failures included). A shard that cannot be read back as this
        input's result is left out, and so is one whose input changed since (in :attr:`changed`): that input is
        evaluated again."""
        found: dict[int, SequenceResult] = {}
        for i, (src, (occurrence, name)) in enumerate(zip(self.sources, self.keys, strict=True)):
            try:
                head, res = shard_codec.read(self.dir / name)
            except (FileNotFoundError, shard_codec.ShardError):
                continue
            if (head.get("format"), head.get("kind"), head.get("source"), head.get("occurrence")) != (
                    FORMAT, "result", src, occurrence) or not isinstance(res, SequenceResult):
                continue
            why = changed(head.get("identity"), identity(src))
            if why:
                self.changed[i] = why
                continue
            found[i] = res
        return found

    def write(self, i: int, res: SequenceResult) -> None:
        """Keep input ``i``'s result (with the identity of its input now)."""
        occurrence, name = self.keys[i]
        src = self.sources[i]
        header = {"format": FORMAT, "kind": "result", "source": src, "occurrence": occurrence,
                  "identity": identity(src)}
        _write_atomic(self.dir / name, shard_codec.encode(header, res))

    def tuning(self) -> Any:
        """The tuning an earlier pass of this run saved (None: none saved, or not readable as one)."""
        try:
            head, value = shard_codec.read(self.dir / TUNING)
        except (FileNotFoundError, shard_codec.ShardError):
            return None
        ok = (head.get("format"), head.get("kind")) == (FORMAT, "tuning") and isinstance(value, list) and all(
            isinstance(t, tuple) and len(t) == 2 and isinstance(t[0], dict) and isinstance(t[1], EstimatorSpec)
            for t in value)
        return value if ok else None

    def save_tuning(self, tuning: Any) -> None:
        _write_atomic(self.dir / TUNING, shard_codec.encode({"format": FORMAT, "kind": "tuning"}, tuning))
