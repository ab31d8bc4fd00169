"""``riann-bag-eval``'s options that name what to read: the bag topics, the --estimate-file trajectory files (each
read once, before any work) and the checks on recorded estimates. ValueError for anything wrong (exit status 2)."""

from __future__ import annotations

import argparse
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


def topics(args: argparse.Namespace) -> ev.BagTopics:
    """Which bag topics to read (ValueError on bad values)."""
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
        files=_estimate_files(args, estimates),
    )


def _file_and_label(text: str) -> tuple[str, str]:
    """``FILE[:LABEL]`` (a path that exists as given is all path)."""
    path, sep, label = text.rpartition(":")
    if not sep or Path(text).exists() or "/" in label or not path:
        path, label = text, ""
    return path, label.strip() or Path(path).stem


def _owner(file: str, inputs: list[str]) -> str | None:
    """The input a file belongs to: the only one, or the one whose name (without suffix) starts the file's name
    (the longest such); ValueError when none does."""
    if len(inputs) <= 1:
        return None
    name = Path(file).name
    owners = [i for i in inputs if name.startswith(Path(i).stem)]
    if not owners:
        raise ValueError(f"--estimate-file {file}: with several inputs a file belongs to the input whose name starts "
                         f"its name (run1.mcap: run1_myfilter.tum); none of {', '.join(inputs)} does")
    return max(owners, key=lambda i: len(Path(i).stem))


def _estimate_files(args: argparse.Namespace, topics: tuple[str, ...]) -> tuple[ev.EstimateFile, ...]:
    """The --estimate-file files, each read once here (ValueError: exit status 2 before any work)."""
    cols = None
    if args.estimate_cols:
        cols = tuple(c.strip() for c in args.estimate_cols.split(","))
        if len(cols) != 5 or not all(cols):
            raise ValueError(f"--estimate-cols needs 5 column names TIME,QW,QX,QY,QZ, got {args.estimate_cols!r}")
    files = []
    for text in args.estimate_file:
        path, label = _file_and_label(text)
        f = ev.EstimateFile(path, label, _owner(path, [str(i) for i in args.inputs]), cols, args.estimate_time_unit)
        try:
            f.read()
        except ev.EvalError as exc:
            raise ValueError(str(exc)) from exc
        files.append(f)
    taken = [*topics, *(f.label for f in files)]
    dup = next((lbl for lbl in taken if taken.count(lbl) > 1), None)
    if dup is not None:
        raise ValueError(f"estimate label {dup!r} given twice: give the files labels of their own (FILE:LABEL)")
    return tuple(files)


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
