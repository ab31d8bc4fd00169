"""The ``--out`` folder policy of ``riann-bag-eval`` (ROS-free): which files are a run's results, and never mixing
two runs in one folder. Used by the run's files (:mod:`~riann_ros.evaluation.report`) and by ``--compare``
(:mod:`~riann_ros.evaluation.compare`)."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Sequence
from pathlib import Path

PLOT_STEMS = ("rmse_boxplots", "error_over_time", "rmse_vs_rate", "compare_rmse", "error_vs_sigma")
PLOT_PATTERNS = ("roll_pitch_*", "attitude_*")  # one figure per sequence
RESULT_FILES = ("results.csv", "results.json", "report.md", "compare.csv")
PLOT_EXTS = ("png", "svg")


def previous_results(out: Path) -> list[Path]:
    """The result files of an earlier run in ``out``: results.csv/json, report.md, compare.csv and every plot
    riann-bag-eval writes (``rmse_boxplots``, ``error_over_time``, ``rmse_vs_rate``, ``compare_rmse``,
    ``error_vs_sigma``, ``roll_pitch_*``, ``attitude_*``; .png and .svg). Nothing else in ``out`` is a result file."""
    if not out.is_dir():
        return []
    found = [out / f for f in RESULT_FILES] + [out / f"{s}.{e}" for s in PLOT_STEMS for e in PLOT_EXTS]
    found += [p for pat in PLOT_PATTERNS for e in PLOT_EXTS for p in sorted(out.glob(f"{pat}.{e}"))]
    return [p for p in found if p.is_file()]


class OutputExists(FileExistsError):
    """``--out`` holds the results of an earlier run and replacing them was not asked for."""

    def __init__(self, out: Path, files: Sequence[Path]) -> None:
        names = ", ".join(p.name for p in files[:4]) + (", …" if len(files) > 4 else "")
        super().__init__(f"{out} already holds the results of an earlier run ({names}); not overwriting them: use "
                         "--force to replace them (only riann-bag-eval's result files are removed, nothing else in "
                         "the folder) or choose another --out")


def prepare_out(out: Path, replace: bool) -> list[Path]:
    """Make ``out`` ready for a run's files: :class:`OutputExists` when it holds an earlier run's result files and
    not ``replace``; with ``replace`` those files (only those) are removed. Returns the files removed."""
    old = previous_results(out)
    if old and not replace:
        raise OutputExists(out, old)
    for p in old:
        p.unlink(missing_ok=True)
    out.mkdir(parents=True, exist_ok=True)
    return old


def _unwritable(folder: Path) -> str:
    """Why nothing can be made in ``folder`` or, where it does not exist yet, in the nearest existing folder above it
    (tried: a file made there and removed again); "" when it can."""
    where = folder
    while not where.exists() and not where.is_symlink() and where != where.parent:
        where = where.parent
    if not where.is_dir():
        return f"{where} is not a folder"
    try:
        fd, probe = tempfile.mkstemp(prefix=".riann_write_check.", dir=where)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        return f"cannot write into {where}: {exc.strerror or exc}"
    return ""


def check_folder(path: Path, option: str) -> None:
    """ValueError naming ``option`` and ``path`` when an output folder cannot be there: something other than a folder
    is at ``path`` (or above it), or it cannot be written into (or made)."""
    if path.exists() and not path.is_dir():
        raise ValueError(f"{option} {path}: exists and is not a folder")
    why = _unwritable(path)
    if why:
        raise ValueError(f"{option} {path}: {why}")


def check_file(path: Path, option: str) -> None:
    """ValueError naming ``option`` and ``path`` when an output file cannot be written at ``path``: a folder is there,
    or its folder cannot be written into (or made)."""
    if path.is_dir():
        raise ValueError(f"{option} {path}: is a folder, not a file")
    why = _unwritable(path.parent)
    if why:
        raise ValueError(f"{option} {path}: {why}")
