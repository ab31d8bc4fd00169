"""``riann-bag-convert``'s command line: IMU datasets → rosbag2 bags in the layout of :mod:`riann_ros.bagio`.
The parser and its options in groups; the run is :mod:`riann_ros.cli.convert`, the work
:mod:`riann_ros.datasets.conversion`. The examples and the paragraph after them are the ``--help`` epilog.

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
from pathlib import Path

from riann_ros import bagio, defaults
from riann_ros.datasets import FORMATS
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
    _output(p)
    _csv(p)
    _euroc(p)
    _synthetic(p)
    return p


def _output(p: argparse.ArgumentParser) -> None:
    """The inputs, the output bag, its storage and compression, and what may be replaced or written."""
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
        help="write the bag even when the unit checks (sample rate, gravity at rest, gyro range, gyro against "
        "accelerometer, magnetic field) fail; "
        "their findings are then warnings",
    )


def _csv(p: argparse.ArgumentParser) -> None:
    """Generic CSV: the columns and their units."""
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


def _euroc(p: argparse.ArgumentParser) -> None:
    """EuRoC/ASL: the ground truth."""
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


def _synthetic(p: argparse.ArgumentParser) -> None:
    """The synthetic generator."""
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
