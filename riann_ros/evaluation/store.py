"""A run's results kept as they come (ROS-free): ``OUT/shards/``, one file per finished input, so a run stopped at
any point keeps every input it finished, and ``--resume`` evaluates only the others.

- ``OUT/shards/run.json``: what the run was asked (the settings, the tuning specs; :func:`fingerprint`) and the
  format. A resumed run must ask the same: :func:`check` names every setting that differs.
- ``OUT/shards/<key>.pkl``: one input's :class:`~riann_ros.evaluation.results.SequenceResult`, pickled whole (an
  opaque record: whatever it holds comes back), with the input's path and occurrence. The key is a hash of the path
  as given and of how many times it came earlier in the input list. A file is written under a temporary name,
  flushed to disk and then renamed, so it is there whole or not at all; a shard is replaced only by a newer result of
  the same input (a retried failure; the plot series moving to an earlier input).
- ``OUT/shards/tuning.pkl``: the tuning's results (``--tune``), so a resumed run does not tune again.

The shards are pickles: read them with the riann_ros that wrote them, and only shards of your own runs (unpickling
runs code).
"""

from __future__ import annotations

import hashlib
import json
import os
import pickle
import shutil
from collections.abc import Mapping, Sequence
from dataclasses import fields, is_dataclass
from pathlib import Path
from typing import Any

from riann_ros.evaluation.results import EvalSettings, SequenceResult

SHARDS = "shards"
MANIFEST = "run.json"
TUNING = "tuning.pkl"
FORMAT = 1
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
        keys.append((k, hashlib.sha256(f"{k}\0{src}".encode()).hexdigest()[:32] + ".pkl"))
    return keys


def unfinished(out: Path) -> int:
    """How many input results an earlier run left in ``out`` (-1: its shards folder holds no run we know)."""
    d = out / SHARDS
    if not d.is_dir():
        return 0
    n = sum(1 for _ in d.glob("*.pkl"))
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


class ShardStore:
    """``OUT/shards`` of one run over ``sources``: opened ``mode`` :data:`NEW` (refused when it holds an earlier run),
    :data:`REPLACE` (an earlier run's shards removed first) or :data:`RESUME` (refused when the settings differ)."""

    def __init__(self, out: Path, fp: dict[str, Any], mode: str, sources: Sequence[str]) -> None:
        check(out, fp, mode)
        self.dir = out / SHARDS
        self.sources = list(sources)
        self.keys = shard_keys(self.sources)
        if mode == REPLACE and self.dir.is_dir():
            shutil.rmtree(self.dir)
        self.dir.mkdir(parents=True, exist_ok=True)
        for tmp in self.dir.glob(".*.tmp"):  # a write cut off by a kill
            tmp.unlink(missing_ok=True)
        if not (self.dir / MANIFEST).is_file():
            manifest = {"format": FORMAT, "settings": fp}
            _write_atomic(self.dir / MANIFEST, (json.dumps(manifest, indent=1) + "\n").encode())

    def load(self) -> dict[int, SequenceResult]:
        """The results the shards hold (by input index; failures included); a shard that cannot be read is left out
        (that input is evaluated again)."""
        found: dict[int, SequenceResult] = {}
        for i, (src, (occurrence, name)) in enumerate(zip(self.sources, self.keys, strict=True)):
            try:
                with open(self.dir / name, "rb") as f:
                    fmt, source, occ, res = pickle.load(f)
            except FileNotFoundError:
                continue
            except Exception:  # written by another riann_ros, or damaged
                continue
            if (fmt, source, occ) == (FORMAT, src, occurrence):
                found[i] = res
        return found

    def write(self, i: int, res: SequenceResult) -> None:
        """Keep input ``i``'s result."""
        occurrence, name = self.keys[i]
        _write_atomic(self.dir / name, pickle.dumps((FORMAT, self.sources[i], occurrence, res), protocol=5))

    def tuning(self) -> Any:
        """The tuning an earlier pass of this run saved (None: none saved)."""
        try:
            return pickle.loads((self.dir / TUNING).read_bytes())
        except FileNotFoundError:
            return None

    def save_tuning(self, tuning: Any) -> None:
        _write_atomic(self.dir / TUNING, pickle.dumps(tuning, protocol=5))
