"""Every input prints under a name of its own (ROS-free).

A sequence is named by the recording (``/dataset/info``, the BROAD trial, the CSV's file stem at conversion), so two
bags converted from one CSV file carry one name. :func:`unique_names` renames every input of a clashing name after
its own file (``a.mcap`` → ``a``), then after its folder and file (``run1/imu.mcap`` → ``run1/imu``) where files
share a name too, then with a number, and warns. Only the name shown and written changes: the scenario's random
gyro bias stays seeded by the recorded name, so a bag gives the same numbers alone and in any list.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

from riann_ros.evaluation.results import SequenceResult


def _file_name(source: str) -> str:
    p = Path(source)
    return p.stem if p.suffix else p.name


def _folder_and_file(source: str) -> str:
    p = Path(source)
    return f"{p.parent.name}/{_file_name(source)}" if p.parent.name else _file_name(source)


def _clashes(names: Sequence[str]) -> set[str]:
    return {n for n in names if names.count(n) > 1}


def unique_names(results: Sequence[SequenceResult]) -> list[str]:
    """Rename the evaluated results whose names clash (in place: the result, its rows, its series and warnings);
    returns the warnings, also added to each renamed result's ``warnings``."""
    done = [r for r in results if not r.error]
    chosen = [r.name for r in done]
    if not _clashes(chosen):
        return []
    rules: list[Callable[[str], str]] = [_file_name, _folder_and_file]
    for rule in rules:
        still = _clashes(chosen)
        chosen = [rule(r.source) if n in still else n for r, n in zip(done, chosen, strict=True)]
    counts: dict[str, int] = {}
    still = _clashes(chosen)
    for i, n in enumerate(chosen):
        if n in still:
            counts[n] = counts.get(n, 0) + 1
            chosen[i] = f"{n}#{counts[n]}"
    warnings = []
    original = [r.name for r in done]
    for r, old, new in zip(done, original, chosen, strict=True):
        if new == old:
            continue
        others = [o.source for o, n in zip(done, original, strict=True) if n == old and o is not r]
        text = (f"{new}: named after its file {r.source}: the recorded name {old} is also "
                f"{', '.join(others) or 'another input'}'s (results.json sequences[].recorded_name keeps it)")
        _rename(r, new)
        r.warnings.insert(0, text)
        warnings.append(text)
    return warnings


def _rename(r: SequenceResult, new: str) -> None:
    old = r.name
    r.recorded_name, r.name = old, new
    for row in r.rows:
        row.sequence = new
    for series in (r.series, r.attitude_series):
        if series is not None:
            series["sequence"] = new
    r.warnings = [new + w[len(old):] if w.startswith(old + ":") or w.startswith(old + " ") else w
                  for w in r.warnings]
