"""``riann-mag-calibrate``: fit the magnetometer's hard and soft iron from a recorded bag and save the calibration.

Example::

    riann-mag-calibrate my_robot.mcap --out my_mag.yaml

The command line (options, exit status) is :mod:`riann_ros.cli.magcal_parser`. The bag is read like
``riann-bag-eval`` reads it (:func:`riann_ros.evaluation.sources.read_whole`: the magnetometer paired with the IMU
samples the nodes' way); the fit and its checks are :func:`riann_ros.magcal.bag_fit.calibrate_recording`, the file
:func:`riann_ros.magcal.store.save_calibration` (atomic; an existing calibration file is replaced only with
``--force``, any other file never), the figures :mod:`riann_ros.magcal.plots`. The outputs are checked before any
work (what is there, write permission: exit status 2). Nothing is written when the input cannot be read, gives
nothing to calibrate from, the fit fails, validation by physics (:mod:`riann_ros.magcal.validate`) refuses the
``--prior`` (its file, or its calibrated field on this recording) or the result, or an output cannot be written (exit
status 1, one line naming the input or the target, never a temporary file): the figures are drawn into temporary
files beside their targets, then the calibration file is written, then the figures take their names. Reference:
docs/magnetometer.md.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import sys
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from riann_ros.cli.magcal_parser import (
    EXIT_CALIBRATED,
    EXIT_FAILED,
    EXIT_INTERRUPTED,
    EXIT_NOT_CONVERGED,
    EXIT_USAGE,
    build_parser,
)
from riann_ros.magcal.bag_fit import NoMagnetometer, NotCalibratable, RecordingFit
from riann_ros.magcal.records import (
    CALIBRATED,
    HARD_IRON_PRIOR_SD_T,
    MAX_DELAY_S,
    SOFT_IRON_PRIOR_SD,
    UT,
    MagCalPrior,
)


def _err(text: str) -> None:
    print(f"riann-mag-calibrate: {text}", file=sys.stderr)


def _figures(args: argparse.Namespace) -> list[Path]:
    """The figure files this run writes (none without --out or --plots, or with --no-plots)."""
    if args.no_plots or (args.out is None and args.plots is None):
        return []
    stem = args.out.stem if args.out is not None else args.bag.stem
    folder = args.plots if args.plots is not None else args.out.parent
    return [folder / f"{stem}_sphere.png", folder / f"{stem}_heading.png"]


def _check_outputs(args: argparse.Namespace) -> None:
    """Refuse (ValueError, exit status 2) outputs that exist or cannot be written, and a bad --mag-delay, before any
    work."""
    from riann_ros.evaluation.outdir import check_file, check_folder
    from riann_ros.magcal.store import CalibrationFileError, is_calibration_file

    _delay(args)
    if args.out is not None and args.out.exists():
        if args.out.is_dir() or not is_calibration_file(args.out):
            raise ValueError(str(CalibrationFileError(f"{args.out}: exists and is not a magnetometer calibration "
                                                      "file; not replaced (not even with --force)")))
        if not args.force:
            raise ValueError(f"{args.out}: exists; --force replaces it")
    if args.out is not None:
        check_file(args.out, "--out")
    if args.plots is not None and not args.no_plots:
        check_folder(args.plots, "--plots")
    for f in _figures(args):
        if f.is_dir():
            raise ValueError(f"{f}: is a folder, not a figure; not replaced")
        if f.exists() and not args.force:
            raise ValueError(f"{f}: exists; --force replaces it (or --no-plots)")


def _delay(args: argparse.Namespace) -> float | None:
    """--mag-delay in s (None: auto); ValueError for anything else."""
    if args.mag_delay.strip().lower() == "auto":
        return None
    try:
        d = float(args.mag_delay)
    except ValueError:
        d = math.nan
    if not 0.0 <= d <= MAX_DELAY_S:
        raise ValueError(f"--mag-delay must be auto or 0 to {MAX_DELAY_S:g} s, got {args.mag_delay!r}")
    return d


#: a saved calibration whose σ is wider than this many times the unknown prior's (hard iron 50 µT, soft iron 0.1 per
#: entry) is refused as --prior: it says less than no prior, and numbers that wide break the fit's linear algebra
PRIOR_WIDER = 10.0


def _prior(args: argparse.Namespace) -> MagCalPrior | None:
    """The --prior file as the fit's prior (CalibrationFileError naming the file: unreadable, not a calibration, or
    too wide to start from)."""
    from riann_ros.magcal.store import CalibrationFileError, load_calibration

    if args.prior is None:
        return None
    prior = MagCalPrior.from_calibration(load_calibration(args.prior))
    if prior.covariance is not None:
        sd = np.sqrt(np.clip(np.diag(np.asarray(prior.covariance).reshape(12, 12)), 0.0, None))
        limit = PRIOR_WIDER * np.array([SOFT_IRON_PRIOR_SD] * 9 + [HARD_IRON_PRIOR_SD_T] * 3)
        k = int(np.argmax(sd / limit))
        if not sd[k] <= limit[k]:
            what, unit, scale = ("soft iron", "", 1.0) if k < 9 else ("hard iron", " µT", UT)
            raise CalibrationFileError(
                f"{args.prior}: its covariance is too wide to start from (a {what} σ of {sd[k] / scale:.3g}{unit}, "
                f"more than {PRIOR_WIDER:g} times the unknown prior's {limit[k] / PRIOR_WIDER / scale:g}{unit}); "
                "leave out --prior to start from the unknown prior")
    return prior


class Refused(ValueError):
    """A calibration validation refuses (message: which file, why)."""


def _check_prior(args: argparse.Namespace, prior: MagCalPrior | None, mag: NDArray[np.float64] | None) -> None:
    """Refuse a ``--prior`` whose calibrated field on this recording's readings is not an Earth field."""
    from riann_ros.magcal.validate import field_norm_refusals, typical_field_norm_t

    norm = None if prior is None or mag is None else typical_field_norm_t(prior.hard_iron_t, prior.soft_iron, mag)
    reasons = [] if norm is None else field_norm_refusals(norm)
    if reasons:
        raise Refused(f"--prior {args.prior}: refused on {args.bag.name}'s readings: {'; '.join(reasons)}; nothing "
                      "written")


def _check_result(args: argparse.Namespace, rf: RecordingFit) -> None:
    """Refuse a fitted calibration that validation refuses (its calibrated readings' norm included)."""
    from riann_ros.magcal.validate import calibration_refusals, typical_field_norm_t

    cal = rf.fit.calibration
    norm = typical_field_norm_t(cal.hard_iron_t, cal.soft_iron, rf.raw_ut * UT)
    reasons = calibration_refusals(cal, norm)
    if reasons:
        raise Refused(f"{args.bag}: the fitted calibration is refused: {'; '.join(reasons)}; nothing written")


def format_fit(rf: RecordingFit) -> str:
    """The fit as printed: the estimate with its σ, the state, the residual and the checks."""
    f = rf.fit
    cal = f.calibration
    sd = cal.hard_iron_sd_t
    s_sd = [math.sqrt(max(cal.covariance[i * 12 + i], 0.0)) for i in range(9)]
    lines = [f"recording: {rf.seconds:.1f} s, {rf.readings} magnetometer readings, {f.windows} windows of rotation "
             f"({f.outliers} left out or down-weighted as disturbed)",
             f"magnetometer latency behind the gyro: {rf.delay_s * 1e3:.1f} ms "
             f"({'estimated: the least residual' if rf.delay_estimated else 'given'})",
             "hard iron (µT): " + "  ".join(f"{a} {h / UT:+7.2f} ± {s / UT:.2f}"
                                           for a, h, s in zip("xyz", cal.hard_iron_t, sd, strict=True)),
             f"soft iron ({cal.soft_iron_model}; ± σ per entry):"]
    for r in range(3):
        lines.append("    " + "  ".join(f"{cal.soft_iron[3 * r + c]:+.4f} ± {s_sd[3 * r + c]:.4f}" for c in range(3)))
    lines += [f"state: {cal.state}",
              f"residual: {f.residual_rms_ut:.2f} µT RMS per window (variance of unit weight {f.unit_weight:.2f})",
              f"field |m|: raw σ {rf.norm_sd_raw_ut:.2f} µT, calibrated {f.field_norm_ut:.2f} ± "
              f"{f.field_norm_sd_ut:.2f} µT (the sphere)",
              f"heading before / after: north moves {rf.north_spread_raw_deg:.1f}° / {rf.north_spread_cal_deg:.1f}° "
              "RMS in the gyro-carried frame while the sensor turns"]
    if rf.unobserved_axes:
        lines.append(f"not observed: hard iron along {', '.join(rf.unobserved_axes)} (the sensor did not turn about "
                     "the axes across it); it stays near the prior, and the node goes on calibrating it online")
    return "\n".join(lines)


class _Failed(Exception):
    """The run cannot go on (message: what, naming the input or the target; nothing written)."""


def _fit(args: argparse.Namespace) -> RecordingFit:
    """Read the bag, check the ``--prior`` on its readings and fit it (_Failed for anything that stops it, nothing
    written)."""
    from riann_ros.estimators.motion import gyro_motion
    from riann_ros.evaluation import BagTopics, EvalError
    from riann_ros.evaluation.sources import read_whole
    from riann_ros.magcal.bag_fit import calibrate_recording
    from riann_ros.magcal.store import CalibrationFileError

    topics = BagTopics(**{k: "/" + v.strip().lstrip("/") for k, v in (("imu", args.imu_topic),
                                                                       ("mag", args.mag_topic)) if v})
    try:
        prior = _prior(args)
        rec = read_whole(args.bag, topics)
        _check_prior(args, prior, rec.mag)
        with np.errstate(all="ignore"):
            return calibrate_recording(rec, gyro_motion, prior, args.soft_iron_model, _delay(args))
    except CalibrationFileError as exc:
        raise _Failed(f"--prior {exc}; nothing written") from None
    except (EvalError, Refused) as exc:
        raise _Failed(str(exc)) from None
    except NotCalibratable as exc:
        hint = "; another topic: --mag-topic" if isinstance(exc, NoMagnetometer) else ""
        raise _Failed(f"{args.bag}: {exc}{hint}; nothing written") from None
    except (ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
        raise _Failed(f"{args.bag}: the fit failed ({type(exc).__name__}: {exc}); nothing written") from None


def _write(args: argparse.Namespace, rf: RecordingFit) -> None:
    """The figures and the calibration file, each into a temporary file beside its target first, then all renamed to
    their targets; _Failed naming the target when any cannot be written, and then nothing is."""
    from riann_ros.magcal import plots
    from riann_ros.magcal.store import CalibrationFileError, save_calibration

    figures = _figures(args)
    made = _make_folders([*([args.out.parent] if args.out is not None else []), *(f.parent for f in figures[:1])])
    staged: list[tuple[Path, Path]] = []
    try:
        for path, plot in zip(figures, (plots.plot_sphere, plots.plot_heading)[:len(figures)], strict=True):
            staged.append((path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}"), path))
            try:
                plot(rf, staged[-1][0], f"{args.bag.name}: ")
            except Exception as exc:  # a full disk, a folder made read-only meanwhile, or matplotlib itself
                verb = "write" if isinstance(exc, OSError) else "draw"
                raise _Failed(f"cannot {verb} {path}: {_why(exc)}; nothing written") from None
        if args.out is not None:
            staged.insert(0, (args.out.with_name(f".{args.out.name}.{os.getpid()}.tmp"), args.out))
            try:
                save_calibration(staged[0][0], rf.fit.calibration)
            except (CalibrationFileError, OSError) as exc:
                raise _Failed(f"cannot write {args.out}: {_why(exc)}; nothing written") from None
        for tmp, path in staged:  # renames: the last step, all within their folders
            os.replace(tmp, path)
    except BaseException:
        for tmp, _ in staged:
            tmp.unlink(missing_ok=True)
        for folder in reversed(made):
            with contextlib.suppress(OSError):
                folder.rmdir()
        raise


def _why(exc: BaseException) -> str:
    """An error's reason without the temporary file an OSError names."""
    return exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc) or type(exc).__name__


def _make_folders(folders: list[Path]) -> list[Path]:
    """Make the folders that do not exist (parents first); the ones made, to remove again if nothing is written."""
    made: list[Path] = []
    for folder in folders:
        missing = [p for p in (folder, *folder.parents) if not p.exists()]
        for p in reversed(missing):
            try:
                p.mkdir()
            except OSError as exc:
                raise _Failed(f"cannot make the folder {p}: {_why(exc)}; nothing written") from None
            made.append(p)
    return made


def _run(args: argparse.Namespace) -> int:
    try:
        rf = _fit(args)
        print(format_fit(rf))
        _check_result(args, rf)
        _write(args, rf)
    except (_Failed, Refused) as exc:
        _err(str(exc))
        return EXIT_FAILED
    if args.out is not None:
        print(f"wrote {args.out} (load it with the node parameter mag_calibration_file)")
    for path in _figures(args):
        print(f"wrote {path}")
    if rf.fit.calibration.state != CALIBRATED:
        _err(f"warning: the calibration is {rf.fit.calibration.state}, not calibrated: too little rotation to bound "
             "the heading error it adds to the field's own 2.5° (turn the sensor through more headings, and tilt "
             "it where it can be tilted)")
        return EXIT_NOT_CONVERGED
    return EXIT_CALIBRATED


def main(argv: list[str] | None = None) -> int:
    """The CLI (exit status: :mod:`riann_ros.cli.magcal_parser`)."""
    args = build_parser().parse_args(argv)
    try:
        _check_outputs(args)
    except ValueError as exc:
        _err(str(exc))
        return EXIT_USAGE
    try:
        return _run(args)
    except KeyboardInterrupt:
        _err("interrupted; the calibration file is written whole or not at all")
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    sys.exit(main())
