"""stdout and stderr that go quiet when their reader has gone (``riann-bag-eval … | head``, ``… 2>&1 | head``): the
run goes on and still writes its result files, with no traceback (ROS-free)."""

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
    """``sys.stdout`` and ``sys.stderr`` as :class:`QuietPipe` inside the block (each unchanged where it is no file,
    e.g. captured)."""
    saved = {}
    for name in ("stdout", "stderr"):
        stream = getattr(sys, name)
        try:
            stream.fileno()
        except (AttributeError, OSError, ValueError):
            continue
        saved[name] = stream
        setattr(sys, name, QuietPipe(stream))
    try:
        yield
    finally:
        for name, real in saved.items():
            getattr(sys, name).flush()  # what is still buffered: a reader gone by now must not fail the exit's flush
            setattr(sys, name, real)
