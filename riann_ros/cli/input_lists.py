"""``riann-bag-eval --inputs-from FILE``: inputs listed in a file, one path or glob a line, so a corpus of thousands
of bags needs no shell expansion (and no command line as long as the corpus)."""

from __future__ import annotations

import glob
import os
import sys
from pathlib import Path


def _list_lines(name: str) -> tuple[list[str], Path]:
    """The lines of an --inputs-from file (``-``: standard input) and the folder its relative paths start from."""
    if name == "-":
        return sys.stdin.read().splitlines(), Path()
    try:
        return Path(name).read_text().splitlines(), Path(name).parent
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"--inputs-from {name}: cannot read it: {exc}") from exc


def inputs_from(names: list[str]) -> list[str]:
    """The inputs listed in --inputs-from files: one path or glob per line, blank lines and ``#`` comments skipped,
    relative paths relative to the file's folder, a glob's matches sorted. ValueError for an unreadable file or a glob
    that matches nothing (exit status 2 before any work); a plain path is taken as it is (a missing one fails as an
    input, and a cluster's workers may see paths this machine does not)."""
    out: list[str] = []
    for name in names:
        lines, base = _list_lines(name)
        for n, raw in enumerate(lines, 1):
            line = raw.strip()
            if not line or line.startswith("#"):
                continue
            path = line if os.path.isabs(line) or base == Path() else os.path.normpath(base / line)
            if not any(c in line for c in "*?["):
                out.append(str(path))
                continue
            found = sorted(glob.glob(str(path), recursive=True))
            if not found:
                raise ValueError(f"--inputs-from {name}, line {n}: {line!r} matches no file")
            out += found
    return out


def deduplicated(inputs: list[str]) -> tuple[list[str], list[str]]:
    """The inputs with each file once, by its resolved path (a link, ``./a.mcap`` and ``a.mcap`` are one file), in
    the order they first come; and a warning per input left out, naming the one kept."""
    kept: dict[Path, str] = {}
    warnings = []
    for i in inputs:
        key = Path(i).resolve()
        if key in kept:
            same = "" if kept[key] == i else f" (as {kept[key]})"
            warnings.append(f"{i} is given more than once{same}: evaluated once")
        else:
            kept[key] = i
    return list(kept.values()), warnings
