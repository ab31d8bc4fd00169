"""Folders the fault tests make unwritable, for root too (the test machine's tests run as root, for whom a mode of
0o555 is no barrier: ``chattr +i`` then, the immutable attribute, which root's writes respect)."""

from __future__ import annotations

import os
import subprocess
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest


def _writable(folder: Path) -> bool:
    try:
        fd, probe = tempfile.mkstemp(dir=folder)
    except OSError:
        return False
    os.close(fd)
    os.unlink(probe)
    return True


@contextmanager
def read_only(folder: Path) -> Iterator[Path]:
    """``folder`` (made if missing) that nothing can be written into while the context lasts; skips the test where
    that cannot be arranged."""
    folder.mkdir(parents=True, exist_ok=True)
    root = os.geteuid() == 0
    if root:
        if subprocess.run(["chattr", "+i", str(folder)], capture_output=True).returncode != 0:
            pytest.skip("cannot make a folder read-only for root here (chattr +i)")
    else:
        folder.chmod(0o555)
    try:
        if _writable(folder):
            pytest.skip(f"{folder} stays writable")
        yield folder
    finally:
        if root:
            subprocess.run(["chattr", "-i", str(folder)], capture_output=True)
        else:
            folder.chmod(0o755)
