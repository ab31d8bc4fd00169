"""Dataset readers (ROS-free): each returns :class:`riann_ros.recording.Recording` objects.

:func:`read_any` picks the reader from ``format`` or, with ``format=None``, from the input:
``.hdf5``/``.h5``/``.mat`` → BROAD, a folder with ``mav0/imu0/data.csv`` → EuRoC/ASL,
``.csv``/``.txt`` → generic CSV. ``synthetic`` takes no input path (options go to
:func:`riann_ros.datasets.synthetic.generate`).
"""

from __future__ import annotations

import os
from pathlib import Path

from riann_ros.recording import Recording

FORMATS = ("broad", "euroc", "csv", "synthetic")


def detect_format(path: str | os.PathLike[str]) -> str:
    """The input format of ``path`` or ValueError."""
    from riann_ros.datasets.euroc import is_euroc

    p = Path(path)
    if not p.exists():
        from riann_ros.datasets.broad import missing

        raise FileNotFoundError(missing(p))
    if p.is_dir():
        if is_euroc(p):
            return "euroc"
        raise ValueError(f"{p}: cannot detect the format of this folder (not an EuRoC/ASL folder); use --format")
    suffix = p.suffix.lower()
    if suffix in (".hdf5", ".h5", ".mat"):
        return "broad"
    if suffix in (".csv", ".txt"):
        return "csv"
    raise ValueError(f"{p}: cannot detect the input format from suffix {suffix!r}; use --format")


def read_any(path: str | os.PathLike[str] | None, format: str | None = None, **opts) -> Recording:
    """Read ``path`` with the reader for ``format`` (auto-detected when None); ``opts`` go to the reader."""
    fmt = format or (detect_format(path) if path is not None else None)
    if fmt == "synthetic":
        from riann_ros.datasets.synthetic import generate

        return generate(**opts)
    if path is None:
        raise ValueError(f"format {fmt!r} needs an input path")
    if fmt == "broad":
        from riann_ros.datasets.broad import read_broad

        rec = read_broad(path)
        if "frame_id" in opts:
            rec.frame_id = opts["frame_id"]
        return rec
    if fmt == "euroc":
        from riann_ros.datasets.euroc import read_euroc

        return read_euroc(path, **opts)
    if fmt == "csv":
        from riann_ros.datasets.csvfile import read_csv

        return read_csv(path, **opts)
    raise ValueError(f"unknown format {fmt!r}; expected one of {', '.join(FORMATS)}")
