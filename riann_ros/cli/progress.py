"""The progress bar of the command-line tools (stderr)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TextIO

from riann_ros.evaluation.results import SequenceResult


class Progress:
    """A one-line progress bar on stderr (plain lines when stderr is not a terminal)."""

    def __init__(self, total: int, stream: TextIO | None = None, width: int = 30, enabled: bool = True) -> None:
        self.total = max(total, 1)
        self.stream = stream or sys.stderr
        self.width = width
        self.enabled = enabled
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())

    def __call__(self, done: int, total: int, result: SequenceResult | None = None) -> None:
        if not self.enabled:
            return
        name = (result.name or Path(result.source).name) if result else ""
        status = "FAILED" if result is not None and result.error else f"{result.seconds if result else 0.0:.1f}s"
        filled = int(self.width * done / self.total)
        bar = "#" * filled + "-" * (self.width - filled)
        line = f"[{bar}] {done}/{total} {name} ({status})"
        if self.tty:
            self.stream.write("\r\033[K" + line + ("\n" if done >= total else ""))
        else:
            self.stream.write(line + "\n")
        self.stream.flush()
