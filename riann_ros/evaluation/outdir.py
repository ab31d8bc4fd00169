"""The ``--out`` folder policy of ``riann-bag-eval`` (ROS-free): which files are a run's results, and never mixing
two runs in one folder. Used by the run's files (:mod:`~riann_ros.evaluation.report`) and by ``--compare``
(:mod:`~riann_ros.evaluation.compare`)."""

from __future__ import annotations

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
