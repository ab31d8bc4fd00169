"""stdout that goes quiet when its reader has gone (``riann-bag-eval … | head``): the run goes on and still writes
its result files, with no traceback (ROS-free)."""

from __future__ import annotations

import contextlib
import io
import os
import sys
from collections.abc import Iterator
from typing import TextIO


class QuietPipe(io.TextIOBase):
    """Writes to ``stream`` until its reader closes the pipe; from then on to nowhere (the file descriptor is pointed
    at ``/dev/null``, so the interpreter's last flush at exit is quiet too)."""

    def __init__(self, stream: TextIO) -> None:
        self.stream = stream
        self.gone = False

    def write(self, s: str) -> int:
        if not self.gone:
            try:
                self.stream.write(s)
            except BrokenPipeError:
                self._gone()
        return len(s)

    def flush(self) -> None:
        if not self.gone:
            try:
                self.stream.flush()
            except BrokenPipeError:
                self._gone()

    def _gone(self) -> None:
        self.gone = True
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, self.stream.fileno())
        os.close(devnull)


@contextlib.contextmanager
def quiet_when_reader_leaves() -> Iterator[None]:
    """``sys.stdout`` as a :class:`QuietPipe` inside the block (unchanged where stdout is no file, e.g. captured)."""
    try:
        sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):
        yield
        return
    real = sys.stdout
    quiet = QuietPipe(real)
    sys.stdout = quiet
    try:
        yield
    finally:
        quiet.flush()  # what is still buffered: a reader gone by now must not make the exit's flush fail
        sys.stdout = real
