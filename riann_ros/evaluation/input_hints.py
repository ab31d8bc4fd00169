"""What an input the evaluator does not read is, and what to type instead (ROS-free): CSV files, EuRoC/ASL folders
and folders of dataset files go through ``riann-bag-convert`` first, ROS 1 bags through ``rosbags-convert``."""

from __future__ import annotations

import os
from pathlib import Path

from riann_ros.evaluation.errors import EvalError

BROAD_SUFFIXES = (".hdf5", ".h5", ".mat")


def _q(p: Path) -> str:
    import shlex

    return shlex.quote(str(p))


def _folder_hint(p: Path) -> str | None:
    from riann_ros.datasets.euroc import is_euroc

    if (p / "metadata.yaml").exists():
        return None
    if is_euroc(p):
        bag = p.parent / f"{p.resolve().name}.mcap"
        return (f"{p}: an EuRoC/ASL folder, not a bag; convert it first with riann-bag-convert:\n"
                f"    riann-bag-convert {_q(p)} -o {_q(bag)}\n    riann-bag-eval {_q(bag)}")
    files = sorted(f for f in p.iterdir() if f.suffix.lower() in (*BROAD_SUFFIXES, ".csv"))
    if files:
        out = p.parent / f"{p.resolve().name}_bags"
        return (f"{p}: a folder of dataset files, not a bag; give the BROAD files themselves "
                f"(riann-bag-eval {_q(p)}/*.hdf5 …) or convert them first with riann-bag-convert:\n"
                f"    riann-bag-convert {_q(p)} -o {_q(out)}\n    riann-bag-eval {_q(out)}/*.mcap")
    return None


def input_hint(path: str | os.PathLike[str]) -> str | None:
    """For an input the evaluator does not read but riann-bag-convert does (a CSV file, an EuRoC/ASL folder, a
    folder of dataset files; a ROS 1 bag): what to type instead. None for anything else."""
    p = Path(path)
    if p.is_dir():
        return _folder_hint(p)
    suffix = p.suffix.lower()
    if suffix in (".csv", ".txt") and p.is_file():
        bag = p.with_suffix(".mcap")
        return (f"{p}: a CSV file, not a bag; convert it first with riann-bag-convert (see riann-bag-convert --help "
                f"for the column and unit options, e.g. --time-unit ms --gyr-unit deg/s --quat-cols qw,qx,qy,qz):\n"
                f"    riann-bag-convert {_q(p)} -o {_q(bag)}\n    riann-bag-eval {_q(bag)}")
    if suffix == ".bag" and p.is_file():
        dst = p.with_suffix("")
        return (f"{p}: a ROS 1 bag; convert it to rosbag2 first, then name its topics:\n"
                f"    rosbags-convert --src {_q(p)} --dst {_q(dst)}\n"
                f"    riann-bag-eval {_q(dst)} --imu-topic IMU_TOPIC --ground-truth-topic REFERENCE_TOPIC")
    return None


def check_input(p: Path) -> None:
    """EvalError for a missing input, or one to convert first (:func:`input_hint`)."""
    if not p.exists():
        from riann_ros.datasets.broad import missing

        raise EvalError(missing(p))
    hint = input_hint(p)
    if hint:
        raise EvalError(hint)
