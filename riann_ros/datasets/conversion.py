"""Datasets → rosbag2 bags as a library call (ROS-free): ``riann-bag-convert``'s work without its command line.

:func:`plan` turns inputs into jobs (one per input file; a folder of BROAD or CSV files gives one job per file),
:func:`layout` decides whether the output is one bag or a folder of bags, :func:`convert` reads one job with its
format's reader (options in :class:`ConvertSettings`), checks its units (:mod:`riann_ros.datasets.units`) and
writes the bag (:func:`riann_ros.bagio.write_recording`). The command (:mod:`riann_ros.cli.convert`) is a thin
layer over them; from Python::

    from riann_ros.datasets.conversion import ConvertSettings, Job, convert

    rec = convert(Job(Path("02_undisturbed_slow_rotation_B.hdf5"), "broad"), Path("broad02.mcap"), ConvertSettings())
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, NamedTuple

from riann_ros import bagio, defaults
from riann_ros.datasets import detect_format, read_any
from riann_ros.datasets.csvfile import DEFAULT_ACC, DEFAULT_GYR, DEFAULT_TIME
from riann_ros.datasets.units import Finding, check_units
from riann_ros.recording import Recording


def _kwargs(options: Any) -> dict[str, Any]:
    return {f.name: getattr(options, f.name) for f in fields(options)}


@dataclass(frozen=True)
class CsvOptions:
    """The generic CSV reader's columns and units (:func:`riann_ros.datasets.csvfile.read_csv`)."""

    time_col: str = DEFAULT_TIME
    time_unit: str = "s"
    acc_cols: tuple[str, ...] = DEFAULT_ACC
    acc_unit: str = "m/s2"
    gyr_cols: tuple[str, ...] = DEFAULT_GYR
    gyr_unit: str = "rad/s"
    quat_cols: tuple[str, ...] | None = None  # reference quaternion columns, in quat_order order
    quat_order: str = "wxyz"
    mask_col: str | None = None  # None: "scored" if present
    delimiter: str | None = None  # None: detected
    mag_cols: tuple[str, ...] | None = None  # None: mag_x, mag_y, mag_z if present
    mag_unit: str = "uT"


@dataclass(frozen=True)
class EurocOptions:
    """The EuRoC/ASL reader's ground truth (:func:`riann_ros.datasets.euroc.read_euroc`)."""

    ground_truth: Path | None = None  # None: the folder's own state_groundtruth_estimate0
    gt_cols: tuple[str, ...] | None = None  # TIME, QW, QX, QY, QZ column names (None: detect the layout)
    gt_time_unit: str | None = None  # None: from the column name
    max_gap_s: float = defaults.MAX_GAP_S  # no reference across ground-truth gaps longer than this
    imu_to_body: tuple[float, float, float, float] | None = None  # IMU orientation in the body frame, w, x, y, z


@dataclass(frozen=True)
class SyntheticOptions:
    """The synthetic generator's settings (:func:`riann_ros.datasets.synthetic.generate`)."""

    rate: float = defaults.SYNTHETIC.rate  # Hz
    duration: float = defaults.SYNTHETIC.duration  # s
    seed: int = defaults.SYNTHETIC.seed
    motion: str = defaults.SYNTHETIC.motion
    bias: float | tuple[float, float, float] = defaults.SYNTHETIC.bias  # rad/s: a magnitude or a vector
    gyr_noise: float = defaults.SYNTHETIC.gyr_noise  # rad/s
    acc_noise: float = defaults.SYNTHETIC.acc_noise  # m/s²
    max_tilt_deg: float = defaults.SYNTHETIC.max_tilt_deg
    speed: float = defaults.SYNTHETIC.speed


@dataclass(frozen=True)
class ConvertSettings:
    """How to convert: the bag's storage and compression, the IMU frame, the sequence name, what may be replaced
    or written despite failed unit checks, and each format's reader options."""

    storage: str = "mcap"  # bagio.STORAGES
    compression: str = "auto"  # zstd | none | auto (zstd for mcap storage, MCAP chunk compression; none for sqlite3)
    frame_id: str = defaults.IMU_FRAME
    name: str | None = None  # sequence name (None: from the input)
    force: bool = False  # replace existing output bags
    force_units: bool = False  # write even when the unit checks fail (the findings are then warnings)
    csv: CsvOptions = field(default_factory=CsvOptions)
    euroc: EurocOptions = field(default_factory=EurocOptions)
    synthetic: SyntheticOptions = field(default_factory=SyntheticOptions)

    @property
    def bag_compression(self) -> str | None:
        if self.compression == "auto":
            return "zstd" if self.storage == "mcap" else None
        return None if self.compression == "none" else self.compression

    def reader_options(self, fmt: str) -> dict[str, Any]:
        """The keyword options of ``fmt``'s reader (:func:`riann_ros.datasets.read_any`)."""
        common: dict[str, Any] = {"frame_id": self.frame_id}
        if self.name and fmt != "broad":
            common["name"] = self.name
        extra = {"csv": self.csv, "euroc": self.euroc, "synthetic": self.synthetic}.get(fmt)
        return {**common, **(_kwargs(extra) if extra is not None else {})}


class Job(NamedTuple):
    """One bag to write: an input (None for synthetic) and its format."""

    input: Path | None
    format: str


def plan(inputs: Sequence[Path], fmt: str) -> list[Job]:
    """The jobs of ``inputs`` read as ``fmt`` (``auto``: detected per input); none for synthetic, which takes no
    input: one job. A folder that is not an EuRoC folder expands to its BROAD (or, failing those, CSV) files.
    FileNotFoundError / ValueError for inputs that cannot be planned."""
    from riann_ros.datasets.broad import broad_files, missing
    from riann_ros.datasets.euroc import is_euroc

    if fmt == "synthetic":
        return [Job(None, "synthetic")]
    jobs = []
    for inp in inputs:
        if not inp.exists():
            raise FileNotFoundError(missing(inp))
        if inp.is_dir() and fmt in ("auto", "broad", "csv") and not is_euroc(inp):
            files = broad_files(inp) if fmt in ("auto", "broad") else sorted(inp.glob("*.csv"))
            if not files and fmt == "auto":
                files = sorted(inp.glob("*.csv"))
            if not files:
                raise ValueError(f"{inp}: folder holds no BROAD (.hdf5/.mat) or CSV files and is not an EuRoC folder")
            jobs += [Job(f, detect_format(f) if fmt == "auto" else fmt) for f in files]
        else:
            jobs.append(Job(inp, detect_format(inp) if fmt == "auto" else fmt))
    return jobs


def layout(inputs: Sequence[Path], jobs: Sequence[Job], output: Path, settings: ConvertSettings) -> bool:
    """Whether ``output`` is a folder of bags (several jobs, or one input folder that is not an EuRoC folder) or
    one bag; ValueError when it does not fit the jobs (or ``settings.name``)."""
    many = bool(len(jobs) > 1 or (len(inputs) == 1 and inputs[0].is_dir() and jobs[0].format != "euroc"))
    if many:
        if output.suffix == ".mcap" or (output.exists() and not output.is_dir()):
            raise ValueError(f"{output}: several inputs need an output folder")
        if settings.name:
            raise ValueError("--name only works with one input")
    if not many and output.suffix == ".mcap" and settings.storage != "mcap":
        raise ValueError(f"{output}: a .mcap output needs --storage mcap")
    return many


def target(job: Job, output: Path, many: bool, storage: str) -> Path:
    """The bag of ``job``: ``output`` itself, or in a folder of bags one named after the input (``<stem>.mcap``,
    or ``<stem>/`` for sqlite3)."""
    if not many or job.input is None:
        return output
    stem = job.input.name if job.input.is_dir() else job.input.stem
    return output / (f"{stem}.mcap" if storage == "mcap" else stem)


class UnitCheckFailed(ValueError):
    """The unit checks found implausible values and ``force_units`` was not set; ``lines``: the messages."""

    def __init__(self, lines: list[str]) -> None:
        self.lines = lines
        super().__init__("\n".join(lines))


# The units each format fixes (the unit checks read the numbers in these; CSV units come from the options).
_FIXED_UNITS = {"broad": {"time_unit": "s"}, "euroc": {"time_unit": "ns"}}
_FIXED_TEXT = {"broad": "sampling_rate in Hz, m/s², rad/s, µT", "euroc": "ns stamps, m/s², rad/s"}


def _advice(finding: Finding, fmt: str) -> str:
    """What fixes ``finding``: the CSV option, or for formats with fixed units, a look at the input."""
    if fmt == "csv":
        return f"use {finding.flag} {finding.suggest}" if finding.suggest else f"check the columns and {finding.flag}"
    return f"the {fmt} format fixes the units ({_FIXED_TEXT.get(fmt, 'SI')}): check the input"


def check_recording_units(rec: Recording, label: str, fmt: str, force_units: bool,
                          warn: Callable[[str], None]) -> None:
    """Refuse a recording whose units look wrong (:class:`UnitCheckFailed`), or with ``force_units`` pass each
    finding to ``warn`` and record them in the bag (``/dataset/info`` ``meta.unit_check``). Synthetic recordings
    are made in the right units and not checked."""
    if fmt == "synthetic":
        return
    findings = check_units(rec, **_FIXED_UNITS.get(fmt, {}))
    if not findings:
        return
    lines = [f"{label}: {f}, {_advice(f, fmt)}" for f in findings]
    if not force_units:
        raise UnitCheckFailed(
            [*lines, f"{label}: no bag written (the units look wrong; --force-units writes it anyway)"]
        )
    for line in lines:
        warn(line)
    rec.meta["unit_check"] = "failed, written with --force-units: " + "; ".join(str(f) for f in findings)


def _ignore(_: str) -> None:
    return None


def convert(job: Job, bag: Path, settings: ConvertSettings, warn: Callable[[str], None] = _ignore) -> Recording:
    """Read one job, check its units and write it as the bag ``bag``; the recording written. FileExistsError when
    ``bag`` exists without ``settings.force``; :class:`UnitCheckFailed`, OSError, ValueError, bagio.BagError."""
    if bag.exists() and not settings.force:
        raise FileExistsError(f"{bag}: output exists, not overwriting (use --force to replace it)")
    rec = read_any(job.input, job.format, **settings.reader_options(job.format))
    if settings.name and job.format == "broad":
        rec.name = settings.name
    check_recording_units(rec, str(job.input), job.format, settings.force_units, warn)
    bagio.write_recording(bag, rec, storage=settings.storage, compression=settings.bag_compression,
                          force=settings.force)
    return rec
