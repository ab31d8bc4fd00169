"""``riann-bag-eval``'s options that name what to read: the bag topics, the --estimate-file trajectory files (each
read once, before any work) and the checks on recorded estimates. ValueError for anything wrong (exit status 2)."""

from __future__ import annotations

import argparse
import glob
import math
from pathlib import Path

from riann_ros import evaluation as ev


def bagio_imu_topic() -> str:
    from riann_ros.bagio.layout import IMU_TOPIC

    return IMU_TOPIC


def _topic(name: str) -> str:
    name = name.strip()
    if not name or name == "/":
        raise ValueError("empty topic name")
    return name if name.startswith("/") else "/" + name


def topics(args: argparse.Namespace, warnings: list[str] | None = None) -> ev.BagTopics:
    """Which bag topics to read (ValueError on bad values); what is worth a warning (inputs without an estimate file,
    files without an input) is added to ``warnings``."""
    warnings = [] if warnings is None else warnings
    estimates = tuple(dict.fromkeys(_topic(t) for t in args.estimate_topic))
    if not (args.max_gap > 0 and math.isfinite(args.max_gap)):
        raise ValueError(f"--max-gap must be a positive number of seconds, got {args.max_gap:g}")
    if not math.isfinite(args.t_offset):
        raise ValueError("--t-offset must be a finite number of seconds")
    return ev.BagTopics(
        imu=_topic(args.imu_topic) if args.imu_topic else bagio_imu_topic(),
        reference=_topic(args.ground_truth_topic) if args.ground_truth_topic else None,
        estimates=estimates,
        t_offset_s=args.t_offset,
        max_gap_s=args.max_gap,
        files=_estimate_files(args, estimates, warnings),
    )


def _file_and_label(text: str) -> tuple[str, str]:
    """``FILE[:LABEL]`` (a path that exists as given is all path); the label is empty when not given."""
    path, sep, label = text.rpartition(":")
    if not sep or Path(text).exists() or "/" in label or not path:
        path, label = text, ""
    return path, label.strip()


TRAJECTORY_SUFFIXES = (".tum", ".csv", ".txt")  # the files of a folder given to --estimate-file


def _expand(path: str) -> list[str] | None:
    """The files of a folder (its .tum, .csv and .txt files) or a glob, sorted; None for a plain file path."""
    p = Path(path)
    if p.is_dir():
        files = sorted(str(f) for f in p.iterdir() if f.is_file() and f.suffix.lower() in TRAJECTORY_SUFFIXES)
    elif glob.has_magic(path):
        files = sorted(f for f in glob.glob(path) if Path(f).is_file())
    else:
        return None
    if not files:
        raise ValueError(f"--estimate-file {path}: no trajectory file there")
    return files


def stem(path: str) -> str:
    """A path's name without its suffix (a bag directory's name)."""
    p = Path(path)
    return p.stem if p.suffix else p.name


def owner(file: str, inputs: list[str]) -> str | None:
    """The input a trajectory file belongs to: the one whose stem equals the file's stem or starts it followed by a
    character other than a letter or digit (``run1.mcap``: ``run1.tum``, ``run1_vins.tum``, not ``run10.tum``), the
    longest such stem; None when none does."""
    name = stem(file)

    def matches(i: str) -> bool:
        s = stem(i)
        return name == s or (name.startswith(s) and not name[len(s)].isalnum())

    owners = [i for i in inputs if matches(i)]
    return max(owners, key=lambda i: len(stem(i))) if owners else None


def _files_of(text: str, inputs: list[str], warnings: list[str]) -> list[tuple[str, str, str | None]]:
    """(file, label, input) of one ``--estimate-file`` argument (a file, a glob or a folder)."""
    path, label = _file_and_label(text)
    many = _expand(path)
    if many is None:  # one file: the only input's, else the input its name belongs to
        if len(inputs) <= 1:
            return [(path, label or Path(path).stem, None)]
        own = owner(path, inputs)
        if own is None:
            raise ValueError(f"--estimate-file {path}: with several inputs a file belongs to the input whose name "
                             f"starts its name (run1.mcap: run1.tum, run1_myfilter.tum); none of {', '.join(inputs)} "
                             "does")
        return [(path, label or Path(path).stem, own)]
    if not label:
        raise ValueError(f"--estimate-file {path}: give the files of a glob or folder one label ({path}:LABEL)")
    out = [(f, label, owner(f, inputs)) for f in many]
    warnings += [f"--estimate-file {label}: {f} belongs to no input (its name starts with no input's name)"
                 for f, _, own in out if own is None]
    matched = {own for _, _, own in out}
    warnings += [f"--estimate-file {label}: no file in {path} for input {i}" for i in inputs if i not in matched]
    return [x for x in out if x[2] is not None]


def _estimate_files(args: argparse.Namespace, topics: tuple[str, ...],
                    warnings: list[str]) -> tuple[ev.EstimateFile, ...]:
    """The --estimate-file files, each read once here (ValueError: exit status 2 before any work); a label may hold
    many files, one per input."""
    cols = None
    if args.estimate_cols:
        cols = tuple(c.strip() for c in args.estimate_cols.split(","))
        if len(cols) != 5 or not all(cols):
            raise ValueError(f"--estimate-cols needs 5 column names TIME,QW,QX,QY,QZ, got {args.estimate_cols!r}")
    inputs = [str(i) for i in args.inputs]
    files: list[ev.EstimateFile] = []
    for text in args.estimate_file:
        for path, label, own in _files_of(text, inputs, warnings):
            f = ev.EstimateFile(path, label, own, cols, args.estimate_time_unit)
            try:
                f.read()
            except ev.EvalError as exc:
                raise ValueError(str(exc)) from exc
            files.append(f)
    _check_labels(topics, files)
    return tuple(files)


def _check_labels(topics: tuple[str, ...], files: list[ev.EstimateFile]) -> None:
    """A label names one estimate per input: a topic's once, a file label once per input (ValueError otherwise)."""
    for f in files:
        if f.label in topics:
            raise ValueError(f"estimate label {f.label!r} given twice: give the files labels of their own (FILE:LABEL)")
        same = [g for g in files if g.label == f.label and (g.input is None or f.input is None or g.input == f.input)]
        if len(same) > 1:
            inp = next((g.input for g in same if g.input), None)
            where = f" for input {inp}" if inp else ""
            raise ValueError(f"estimate label {f.label!r} given twice{where} ({', '.join(g.path for g in same)}): give "
                             "the files labels of their own (FILE:LABEL), or one file per input")


def check_recorded(settings: ev.EvalSettings) -> None:
    """Recorded estimates (topics, files) are the recording as it is: they need the as-recorded scenario, the native
    rate and the unperturbed condition among those asked for, and labels of their own (ValueError otherwise)."""
    if not (settings.topics.estimates or settings.topics.files):
        return
    clash = {s.label for s in settings.estimators} & {s.label for s in settings.recorded}
    if clash:
        raise ValueError(f"estimate label {sorted(clash)[0]!r} is also an estimator's: label the file "
                         "(--estimate-file FILE:LABEL)")
    missing = []
    if ev.AS_RECORDED not in settings.scenarios:
        missing.append("the as-recorded scenario in --scenarios")
    if None not in settings.rates:
        missing.append("native in --rates")
    if not any(not c.parts for c in settings.conditions):
        missing.append("none in --perturb")
    if missing:
        raise ValueError("--estimate-topic / --estimate-file estimates exist only for the recording as it is "
                         f"(as-recorded scenario, native rate, no perturbation): add {' and '.join(missing)}")
