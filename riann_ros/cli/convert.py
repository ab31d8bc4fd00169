"""``riann-bag-convert``: IMU datasets → rosbag2 bags in the layout of :mod:`riann_ros.bagio`.

Examples::

    riann-bag-convert 02_undisturbed_slow_rotation_B.hdf5 -o broad02.mcap
    riann-bag-convert ../shared/datasets/broad -o broad_bags/          # every BROAD file → one bag each
    riann-bag-convert MH_01_easy/ -o mh01.mcap                        # EuRoC/ASL folder
    riann-bag-convert room1/ --ground-truth room1_gt.csv -o room1.mcap  # open_vins-style ground truth
    riann-bag-convert --format csv imu.csv --time-unit ms --gyr-unit deg/s -o imu.mcap
    riann-bag-convert --format synthetic --rate 200 --duration 60 --seed 1 -o bags/synthetic.mcap
    riann-bag-convert --repair cut.mcap -o cut_repaired.mcap            # a recording cut off by a crash

An output ending in ``.mcap`` is a single MCAP file; any other output is a rosbag2 directory. With
several inputs (or a folder of BROAD/CSV files) the output is a folder receiving one bag per input,
named after the input (``<stem>.mcap``, or ``<stem>/`` for sqlite3). MCAP storage is zstd-compressed
unless ``--compression none``. Every input except synthetic ones passes unit checks (sample rate,
gravity at rest, gyro range: :mod:`riann_ros.datasets.units`); an input that fails them is not written
unless ``--force-units``. Exit status 0 on success, 1 when any input failed, 2 on bad usage; messages go
to stderr. Reference: docs/converter.md.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from riann_ros import bagio, defaults
from riann_ros.datasets import FORMATS, detect_format, read_any
from riann_ros.datasets.csvfile import (
    ACC_UNITS,
    DEFAULT_ACC,
    DEFAULT_GYR,
    DEFAULT_MAG,
    DEFAULT_TIME,
    GYR_UNITS,
    MAG_UNITS,
    QUAT_ORDERS,
    TIME_UNITS,
)
from riann_ros.datasets.synthetic import MOTIONS
from riann_ros.datasets.units import Finding, check_units
from riann_ros.recording import Recording


def _cols(n: int):
    def parse(text: str) -> tuple[str, ...]:
        cols = tuple(c.strip() for c in text.split(","))
        if len(cols) != n or not all(cols):
            raise argparse.ArgumentTypeError(f"expected {n} comma-separated column names, got {text!r}")
        return cols

    return parse


def _bias(text: str) -> float | tuple[float, float, float]:
    parts = [p for p in text.replace(",", " ").split() if p]
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        raise argparse.ArgumentTypeError(f"bias must be a number or three numbers, got {text!r}") from None
    if len(vals) == 1:
        return vals[0]
    if len(vals) == 3:
        return (vals[0], vals[1], vals[2])
    raise argparse.ArgumentTypeError(f"bias must be a number or three numbers, got {text!r}")


def _quat(text: str) -> tuple[float, float, float, float]:
    try:
        w, x, y, z = (float(p) for p in text.replace(",", " ").split())
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a quaternion 'w,x,y,z', got {text!r}") from None
    n = (w * w + x * x + y * y + z * z) ** 0.5
    if abs(n - 1.0) > 1e-3:
        raise argparse.ArgumentTypeError(f"quaternion {text!r} is not a unit quaternion (norm {n:.4g})")
    return (w / n, x / n, y / n, z / n)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="riann-bag-convert",
        description="Convert IMU datasets (BROAD .hdf5/.mat, EuRoC/ASL folders, generic CSV, synthetic) "
        "into rosbag2 bags (/imu/data_raw, /ground_truth/attitude, /ground_truth/scored, /dataset/info).",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=__doc__.split("Examples::", 1)[1] if __doc__ else None,
    )
    p.add_argument("inputs", nargs="*", type=Path, help="input file(s) or folder (none for --format synthetic)")
    p.add_argument("-o", "--output", type=Path, required=True, help="output bag (.mcap file or folder) or folder")
    p.add_argument("--format", choices=("auto", *FORMATS), default="auto", help="input format (default: detect)")
    p.add_argument("--storage", choices=bagio.STORAGES, default="mcap", help="bag storage (default mcap)")
    p.add_argument(
        "--compression",
        choices=("none", "zstd"),
        help="zstd | none (default: zstd for mcap storage (MCAP chunk compression), none for sqlite3)",
    )
    p.add_argument("--frame-id", default=defaults.IMU_FRAME, help=f"IMU frame_id (default {defaults.IMU_FRAME})")
    p.add_argument("--name", help="sequence name (default: from the input)")
    p.add_argument("--force", action="store_true", help="replace existing output bags")
    p.add_argument("--repair", action="store_true",
                   help="no conversion: write the readable part of a bag cut off by a crash or a full disk (an MCAP "
                   "file without its footer, a sqlite3 bag shorter than its header says) as a complete bag -o (a "
                   ".mcap file; for a sqlite3 input also a rosbag2 directory), saying how many messages it recovered")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    p.add_argument(
        "--force-units",
        action="store_true",
        help="write the bag even when the unit checks (sample rate, gravity at rest, gyro range) fail; "
        "their findings are then warnings",
    )

    c = p.add_argument_group("generic CSV")
    c.add_argument("--time-col", default=DEFAULT_TIME, help=f"time column (default {DEFAULT_TIME})")
    c.add_argument("--time-unit", default="s", help=f"{'|'.join(TIME_UNITS)} (default s)")
    c.add_argument("--acc-cols", type=_cols(3), default=DEFAULT_ACC, help=f"default {','.join(DEFAULT_ACC)}")
    c.add_argument("--acc-unit", default="m/s2", help=f"{'|'.join(ACC_UNITS)} (default m/s2)")
    c.add_argument("--gyr-cols", type=_cols(3), default=DEFAULT_GYR, help=f"default {','.join(DEFAULT_GYR)}")
    c.add_argument("--gyr-unit", default="rad/s", help=f"{'|'.join(GYR_UNITS)} (default rad/s)")
    c.add_argument("--quat-cols", type=_cols(4), help="reference quaternion columns, in --quat-order order")
    c.add_argument("--quat-order", choices=QUAT_ORDERS, default="wxyz", help="default wxyz")
    c.add_argument("--mask-col", help="score-mask column (default: 'scored' if present)")
    c.add_argument("--mag-cols", type=_cols(3),
                   help=f"magnetometer columns (default: {','.join(DEFAULT_MAG)} if present)")
    c.add_argument("--mag-unit", default="uT", help=f"{'|'.join(MAG_UNITS)} (default uT)")
    c.add_argument("--delimiter", help="column delimiter (default: detect , ; tab or blanks)")

    e = p.add_argument_group("EuRoC/ASL")
    e.add_argument(
        "--ground-truth",
        type=Path,
        help="ground truth: ASL data.csv, open_vins CSV (#time(ns),px,py,pz,qw,qx,qy,qz) or TUM file "
        "(t tx ty tz qx qy qz qw)",
    )
    e.add_argument(
        "--gt-cols",
        type=_cols(5),
        metavar="TIME,QW,QX,QY,QZ",
        help="ground-truth column names (any CSV with a header; default: detect ASL/open_vins/TUM)",
    )
    e.add_argument(
        "--gt-time-unit",
        choices=tuple(TIME_UNITS),
        help="ground-truth time unit (default: from the column name, e.g. time(ns); else ns, s for TUM)",
    )
    e.add_argument("--max-gap", type=float, default=defaults.MAX_GAP_S,
                   help=f"no reference across ground-truth gaps > s ({defaults.MAX_GAP_S:g})")
    e.add_argument(
        "--imu-to-body",
        type=_quat,
        help="IMU orientation in the ground-truth body frame 'w,x,y,z' (default: identity, as in EuRoC)",
    )

    s = p.add_argument_group("synthetic")
    syn = defaults.SYNTHETIC
    s.add_argument("--rate", type=float, default=syn.rate, help=f"Hz (default {syn.rate:g})")
    s.add_argument("--duration", type=float, default=syn.duration, help=f"s (default {syn.duration:g})")
    s.add_argument("--seed", type=int, default=syn.seed, help=f"random seed (default {syn.seed})")
    s.add_argument("--motion", choices=MOTIONS, default=syn.motion, help=f"default {syn.motion}")
    s.add_argument("--bias", type=_bias, default=syn.bias,
                   help=f"gyro bias rad/s: magnitude or 'bx,by,bz' ({syn.bias:g})")
    s.add_argument("--gyr-noise", type=float, default=syn.gyr_noise,
                   help=f"gyro white noise std, rad/s ({syn.gyr_noise:g})")
    s.add_argument("--acc-noise", type=float, default=syn.acc_noise,
                   help=f"accelerometer white noise std, m/s² ({syn.acc_noise:g})")
    s.add_argument("--max-tilt", type=float, default=syn.max_tilt_deg,
                   help=f"roll/pitch amplitude scale, deg ({syn.max_tilt_deg:g})")
    s.add_argument("--speed", type=float, default=syn.speed, help=f"motion frequency scale ({syn.speed:g})")
    return p


def _reader_opts(fmt: str, args: argparse.Namespace) -> dict:
    common = {"frame_id": args.frame_id}
    if args.name:
        common["name"] = args.name
    if fmt == "csv":
        return {
            **common,
            "time_col": args.time_col,
            "time_unit": args.time_unit,
            "acc_cols": args.acc_cols,
            "acc_unit": args.acc_unit,
            "gyr_cols": args.gyr_cols,
            "gyr_unit": args.gyr_unit,
            "quat_cols": args.quat_cols,
            "quat_order": args.quat_order,
            "mask_col": args.mask_col,
            "delimiter": args.delimiter,
            "mag_cols": args.mag_cols,
            "mag_unit": args.mag_unit,
        }
    if fmt == "euroc":
        return {
            **common,
            "ground_truth": args.ground_truth,
            "gt_cols": args.gt_cols,
            "gt_time_unit": args.gt_time_unit,
            "max_gap_s": args.max_gap,
            "imu_to_body": args.imu_to_body,
        }
    if fmt == "synthetic":
        return {
            **common,
            "rate": args.rate,
            "duration": args.duration,
            "seed": args.seed,
            "motion": args.motion,
            "bias": args.bias,
            "gyr_noise": args.gyr_noise,
            "acc_noise": args.acc_noise,
            "max_tilt_deg": args.max_tilt,
            "speed": args.speed,
        }
    return {"frame_id": args.frame_id}  # broad


def _expand(inputs: list[Path], fmt: str) -> list[tuple[Path, str]]:
    """(input, format) jobs; a folder that is not an EuRoC folder expands to its BROAD/CSV files."""
    from riann_ros.datasets.broad import broad_files
    from riann_ros.datasets.euroc import is_euroc

    jobs = []
    for inp in inputs:
        if not inp.exists():
            raise FileNotFoundError(f"{inp}: no such file or directory")
        if inp.is_dir() and fmt in ("auto", "broad", "csv") and not is_euroc(inp):
            files = broad_files(inp) if fmt in ("auto", "broad") else sorted(inp.glob("*.csv"))
            if not files and fmt == "auto":
                files = sorted(inp.glob("*.csv"))
            if not files:
                raise ValueError(f"{inp}: folder holds no BROAD (.hdf5/.mat) or CSV files and is not an EuRoC folder")
            jobs += [(f, detect_format(f) if fmt == "auto" else fmt) for f in files]
        else:
            jobs.append((inp, detect_format(inp) if fmt == "auto" else fmt))
    return jobs


def _bag_name(inp: Path, storage: str) -> str:
    stem = inp.name if inp.is_dir() else inp.stem
    return f"{stem}.mcap" if storage == "mcap" else stem


def _say(args: argparse.Namespace, text: str) -> None:
    if not args.quiet:
        print(text, file=sys.stderr)


def _plan_jobs(parser: argparse.ArgumentParser, args: argparse.Namespace) -> list[tuple[Path | None, str]] | None:
    """The (input, format) jobs: one synthetic job, or the expanded inputs.

    Bad usage ends in ``parser.error`` (exit status 2); an input that cannot be expanded prints an error
    and gives None.
    """
    if args.format == "synthetic":
        if args.inputs:
            parser.error("--format synthetic takes no inputs")
        return [(None, "synthetic")]
    if not args.inputs:
        parser.error("no input given (or use --format synthetic)")
    try:
        return list(_expand(args.inputs, args.format))
    except (OSError, ValueError) as e:
        print(f"riann-bag-convert: error: {e}", file=sys.stderr)
        return None


def _many_outputs(args: argparse.Namespace, jobs: list[tuple[Path | None, str]]) -> bool:
    """Whether the output is a folder of bags: several jobs, or one input folder that is not an EuRoC folder."""
    return bool(
        len(jobs) > 1 or (args.inputs and len(args.inputs) == 1 and args.inputs[0].is_dir() and jobs[0][1] != "euroc")
    )


def _output_problem(args: argparse.Namespace, many: bool) -> str | None:
    """Why the output (or --name) does not fit the jobs, or None."""
    out: Path = args.output
    if many:
        if out.suffix == ".mcap" or (out.exists() and not out.is_dir()):
            return f"{out}: several inputs need an output folder"
        if args.name:
            return "--name only works with one input"
    if not many and out.suffix == ".mcap" and args.storage != "mcap":
        return f"{out}: a .mcap output needs --storage mcap"
    return None


class UnitCheckFailed(ValueError):
    """The unit checks found implausible values and --force-units was not given; ``lines``: the messages."""

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


def _check_units(args: argparse.Namespace, label: str, fmt: str, rec: Recording) -> None:
    """Refuse a recording whose units look wrong (UnitCheckFailed), or warn with --force-units.

    Synthetic recordings are made in the right units and not checked. With --force-units the findings
    are also recorded in the bag (``/dataset/info`` ``meta.unit_check``).
    """
    if fmt == "synthetic":
        return
    findings = check_units(rec, **_FIXED_UNITS.get(fmt, {}))
    if not findings:
        return
    lines = [f"{label}: {f}, {_advice(f, fmt)}" for f in findings]
    if not args.force_units:
        raise UnitCheckFailed(
            [*lines, f"{label}: no bag written (the units look wrong; --force-units writes it anyway)"]
        )
    for line in lines:
        print(f"riann-bag-convert: warning: {line} (written anyway: --force-units)", file=sys.stderr)
    rec.meta["unit_check"] = "failed, written with --force-units: " + "; ".join(str(f) for f in findings)


def _convert(args: argparse.Namespace, inp: Path | None, fmt: str, target: Path, compression: str | None) -> Recording:
    """Read one input, check its units and write it as the bag ``target``; the recording written."""
    if target.exists() and not args.force:
        raise FileExistsError(f"{target}: output exists, not overwriting (use --force to replace it)")
    rec = read_any(inp, fmt, **_reader_opts(fmt, args))
    if args.name and fmt == "broad":
        rec.name = args.name
    _check_units(args, str(inp), fmt, rec)
    bagio.write_recording(target, rec, storage=args.storage, compression=compression, force=args.force)
    return rec


def _summary(label: str, target: Path, rec: Recording, t0: float) -> str:
    n_ref = 0 if rec.quat_ref is None else int((~(rec.quat_ref != rec.quat_ref).any(axis=1)).sum())
    return (
        f"{label} → {target}: {len(rec)} samples at {rec.rate_hz:.6g} Hz, {n_ref} reference, "
        f"{int(rec.score_mask.sum())} scored ({time.perf_counter() - t0:.1f} s)"
    )


_OK, _FAILED, _INTERRUPTED = 0, 1, 130


def _convert_one(args: argparse.Namespace, inp: Path | None, fmt: str, target: Path, compression: str | None) -> int:
    """Convert one job, reporting to stderr: ``_OK``, ``_FAILED`` or ``_INTERRUPTED`` (Ctrl-C)."""
    label = str(inp) if inp is not None else "synthetic"
    t0 = time.perf_counter()
    try:
        rec = _convert(args, inp, fmt, target, compression)
    except KeyboardInterrupt:
        print(f"riann-bag-convert: interrupted while converting {label}; no partial bag left", file=sys.stderr)
        return _INTERRUPTED
    except UnitCheckFailed as e:
        for line in e.lines:
            print(f"riann-bag-convert: error: {line}", file=sys.stderr)
        return _FAILED
    except (OSError, ValueError, bagio.BagError) as e:
        print(
            f"riann-bag-convert: error: {label}: {e}" if str(label) not in str(e) else f"riann-bag-convert: error: {e}",
            file=sys.stderr,
        )
        return _FAILED
    _say(args, _summary(label, target, rec, t0))
    return _OK


def _compression(args: argparse.Namespace) -> str | None:
    """The bag compression: --compression, else zstd for mcap storage (MCAP chunks) and none for sqlite3."""
    if args.compression is None:
        return "zstd" if args.storage == "mcap" else None
    return None if args.compression == "none" else args.compression


def _repair(parser: argparse.ArgumentParser, args: argparse.Namespace) -> int:
    """``--repair IN -o OUT``: the readable part of a cut-off bag as a complete bag."""
    from riann_ros.bagio import repair

    if len(args.inputs) != 1:
        parser.error("--repair takes one bag (the cut-off .mcap, .db3 or bag directory)")
    src = args.inputs[0]
    try:
        t = repair.repair(src, args.output, force=args.force)
    except KeyboardInterrupt:
        print(f"riann-bag-convert: interrupted while repairing {src}; no partial bag left", file=sys.stderr)
        return _INTERRUPTED
    except (OSError, ValueError, bagio.BagError) as e:
        print(f"riann-bag-convert: error: {e}", file=sys.stderr)  # the messages name the file
        return _FAILED
    print(f"{src} → {args.output}: repaired; {repair.describe(t)}; all of them written", file=sys.stderr)
    return _OK


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.repair:
        return _repair(parser, args)
    compression = _compression(args)
    out: Path = args.output

    jobs = _plan_jobs(parser, args)
    if jobs is None:
        return 1
    many = _many_outputs(args, jobs)
    problem = _output_problem(args, many)
    if problem is not None:
        print(f"riann-bag-convert: error: {problem}", file=sys.stderr)
        return 1

    failures = 0
    for inp, fmt in jobs:
        target = out / _bag_name(inp, args.storage) if many and inp is not None else out
        status = _convert_one(args, inp, fmt, target, compression)
        if status == _INTERRUPTED:
            return status
        if status == _FAILED:
            failures += 1
    if failures:
        print(f"riann-bag-convert: {failures} of {len(jobs)} input(s) failed", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
