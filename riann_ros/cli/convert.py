"""``riann-bag-convert``: IMU datasets → rosbag2 bags in the layout of :mod:`riann_ros.bagio`.

The command line (options, examples, exit status) is :mod:`riann_ros.cli.convert_parser`; the work is
:mod:`riann_ros.datasets.conversion` (and :mod:`riann_ros.bagio.repair` for ``--repair``). This module turns the
command line into their settings and reports on stderr: exit status 0 on success, 1 when any input failed, 2 on
bad usage, 130 when interrupted. Reference: docs/converter.md.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from riann_ros import bagio
from riann_ros.cli.convert_parser import build_parser
from riann_ros.datasets import conversion as cv
from riann_ros.recording import Recording

_OK, _FAILED, _INTERRUPTED = 0, 1, 130


def _err(text: str) -> None:
    print(f"riann-bag-convert: {text}", file=sys.stderr)


def _settings(args: argparse.Namespace) -> cv.ConvertSettings:
    """The conversion settings of the command line."""
    return cv.ConvertSettings(
        storage=args.storage,
        compression=args.compression or "auto",
        frame_id=args.frame_id,
        name=args.name,
        force=args.force,
        force_units=args.force_units,
        csv=cv.CsvOptions(args.time_col, args.time_unit, args.acc_cols, args.acc_unit, args.gyr_cols, args.gyr_unit,
                          args.quat_cols, args.quat_order, args.mask_col, args.delimiter, args.mag_cols,
                          args.mag_unit),
        euroc=cv.EurocOptions(args.ground_truth, args.gt_cols, args.gt_time_unit, args.max_gap, args.imu_to_body),
        synthetic=cv.SyntheticOptions(args.rate, args.duration, args.seed, args.motion, args.bias, args.gyr_noise,
                                      args.acc_noise, args.max_tilt, args.speed),
    )


def _plan_jobs(parser: argparse.ArgumentParser, args: argparse.Namespace) -> list[cv.Job] | None:
    """The jobs: one synthetic job, or the expanded inputs. Bad usage ends in ``parser.error`` (exit status 2); an
    input that cannot be expanded prints an error and gives None."""
    if args.format == "synthetic" and args.inputs:
        parser.error("--format synthetic takes no inputs")
    if args.format != "synthetic" and not args.inputs:
        parser.error("no input given (or use --format synthetic)")
    try:
        return cv.plan(args.inputs, args.format)
    except (OSError, ValueError) as e:
        _err(f"error: {e}")
        return None


def _summary(label: str, target: Path, rec: Recording, t0: float) -> str:
    """The line of a converted input: samples, rate, and the samples with a reference and scored ("no reference"
    when none has one: nothing is scored)."""
    n_ref = 0 if rec.quat_ref is None else int((~(rec.quat_ref != rec.quat_ref).any(axis=1)).sum())
    ref = f"{n_ref} reference, {int(rec.score_mask.sum())} scored" if n_ref else "no reference"
    return f"{label} → {target}: {len(rec)} samples at {rec.rate_hz:.6g} Hz, {ref} ({time.perf_counter() - t0:.1f} s)"


def _convert_one(args: argparse.Namespace, job: cv.Job, target: Path, settings: cv.ConvertSettings) -> int:
    """Convert one job, reporting to stderr: ``_OK``, ``_FAILED`` or ``_INTERRUPTED`` (Ctrl-C)."""
    label = str(job.input) if job.input is not None else "synthetic"
    t0 = time.perf_counter()
    try:
        rec = cv.convert(job, target, settings, warn=lambda line: _err(
            f"warning: {line} (written anyway: --force-units)"))
    except KeyboardInterrupt:
        _err(f"interrupted while converting {label}; no partial bag left")
        return _INTERRUPTED
    except cv.UnitCheckFailed as e:
        for line in e.lines:
            _err(f"error: {line}")
        return _FAILED
    except (OSError, ValueError, bagio.BagError) as e:
        _err(f"error: {label}: {e}" if str(label) not in str(e) else f"error: {e}")
        return _FAILED
    if not args.quiet:
        print(_summary(label, target, rec, t0), file=sys.stderr)
    return _OK


def _repair(parser: argparse.ArgumentParser, args: argparse.Namespace) -> int:
    """``--repair IN -o OUT``: the readable part of a cut-off bag as a complete bag."""
    from riann_ros.bagio import repair

    if len(args.inputs) != 1:
        parser.error("--repair takes one bag (the cut-off .mcap, .db3 or bag directory)")
    src = args.inputs[0]
    try:
        t = repair.repair(src, args.output, force=args.force)
    except KeyboardInterrupt:
        _err(f"interrupted while repairing {src}; no partial bag left")
        return _INTERRUPTED
    except (OSError, ValueError, bagio.BagError) as e:
        _err(f"error: {e}")  # the messages name the file
        return _FAILED
    print(f"{src} → {args.output}: repaired; {repair.describe(t)}; all of them written", file=sys.stderr)
    return _OK


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.repair:
        return _repair(parser, args)
    settings = _settings(args)
    jobs = _plan_jobs(parser, args)
    if jobs is None:
        return 1
    try:
        many = cv.layout(args.inputs, jobs, args.output, settings)
    except ValueError as e:
        _err(f"error: {e}")
        return 1
    failures = 0
    for job in jobs:
        status = _convert_one(args, job, cv.target(job, args.output, many, settings.storage), settings)
        if status == _INTERRUPTED:
            return status
        if status == _FAILED:
            failures += 1
    if failures:
        _err(f"{failures} of {len(jobs)} input(s) failed")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
