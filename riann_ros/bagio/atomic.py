"""Atomic output: refuse to overwrite unless forced, write into a temporary sibling, rename on success."""

from __future__ import annotations

import os
import shutil
import tempfile
from contextlib import suppress
from pathlib import Path
from typing import Literal

from riann_ros.bagio.layout import COMPRESSIONS, STORAGES


def _check_target(target: Path, force: bool) -> None:
    if not (target.exists() or target.is_symlink()):
        return
    if not force:
        raise FileExistsError(f"{target}: output exists, not overwriting (use --force / force=True to replace it)")
    if target.is_dir() and not target.is_symlink():
        entries = list(target.iterdir())
        if entries and not (target / "metadata.yaml").exists():
            raise FileExistsError(
                f"{target}: exists and is a non-empty directory that is not a rosbag2 bag; "
                "refusing to replace it even with force"
            )


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        with suppress(FileNotFoundError):
            path.unlink()


class _AtomicBag:
    """Write a bag into a temporary sibling directory and move it into place on success."""

    def __init__(self, target: Path, storage: str, compression: str | None, force: bool) -> None:
        if storage not in STORAGES:
            raise ValueError(f"unknown storage {storage!r}; expected one of {', '.join(STORAGES)}")
        if compression not in COMPRESSIONS:
            raise ValueError(f"unknown compression {compression!r}; expected zstd or none")
        self.single_file = target.suffix == ".mcap"
        if self.single_file and storage != "mcap":
            raise ValueError(f"{target}: a path ending in .mcap needs storage 'mcap', not {storage!r}")
        _check_target(target, force)
        self.target = target
        self.storage = storage
        self.compression = compression
        self.force = force
        self.tmp: Path | None = None

    def __enter__(self):
        from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer

        self.target.parent.mkdir(parents=True, exist_ok=True)
        self.tmp = Path(tempfile.mkdtemp(prefix=f".{self.target.name}.", suffix=".tmp", dir=self.target.parent))
        stem = self.target.stem if self.single_file else self.target.name
        plugin = StoragePlugin.MCAP if self.storage == "mcap" else StoragePlugin.SQLITE3
        self.writer = Writer(self.tmp / stem, version=9, storage_plugin=plugin)
        if self.compression == "zstd":
            mode = CompressionMode.STORAGE if self.storage == "mcap" else CompressionMode.MESSAGE
            self.writer.set_compression(mode, CompressionFormat.ZSTD)
        try:
            self.writer.open()
        except BaseException:
            self._cleanup()
            raise
        return self.writer

    def _cleanup(self) -> None:
        if self.tmp is not None:
            shutil.rmtree(self.tmp, ignore_errors=True)
            self.tmp = None

    def __exit__(self, exc_type, exc, _tb) -> Literal[False]:
        try:
            if exc_type is not None:
                with suppress(Exception):
                    self.writer.abort()
                return False
            self.writer.close()
            bagdir = self.writer.path
            if self.single_file:
                files = sorted(bagdir.glob("*.mcap"))
                if len(files) != 1:  # pragma: no cover - defensive
                    raise RuntimeError(f"{self.target}: expected one mcap file, found {files}")
                src = files[0]
            else:
                src = bagdir
            _check_target(self.target, self.force)
            if self.target.exists() or self.target.is_symlink():
                _remove(self.target)
            os.replace(src, self.target)
            return False
        finally:
            self._cleanup()
