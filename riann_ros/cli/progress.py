"""The progress bar of the command-line tools (stderr): a :data:`~riann_ros.evaluation.results.Progress`
callback for :func:`riann_ros.evaluation.session.evaluate`'s hooks, whichever executor runs the inputs."""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import TextIO

from riann_ros.evaluation.results import SequenceResult


class Progress:
    """A one-line progress bar on stderr (plain lines when stderr is not a terminal): inputs done of all, the time
    since the bar started and the time left at the pace so far."""

    def __init__(self, total: int, stream: TextIO | None = None, width: int = 30, enabled: bool = True) -> None:
        self.total = max(total, 1)
        self.stream = stream or sys.stderr
        self.width = width
        self.enabled = enabled
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.started = time.monotonic()

    def __call__(self, done: int, total: int, result: SequenceResult | None = None) -> None:
        if not self.enabled:
            return
        name = (result.name or Path(result.source).name) if result else ""
        status = "FAILED" if result is not None and result.error else f"{result.seconds if result else 0.0:.1f}s"
        filled = int(self.width * done / self.total)
        bar = "#" * filled + "-" * (self.width - filled)
        spent = time.monotonic() - self.started
        left = spent / done * (total - done) if done else 0.0
        line = f"[{bar}] {done}/{total} {_clock(spent)} ETA {_clock(left)} {name} ({status})"
        if self.tty:
            self.stream.write("\r\033[K" + line + ("\n" if done >= total else ""))
        else:
            self.stream.write(line + "\n")
        self.stream.flush()


def _clock(seconds: float) -> str:
    """``m:ss``, or ``h:mm:ss`` from an hour on."""
    m, s = divmod(round(seconds), 60)
    h, m = divmod(m, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m}:{s:02d}"
