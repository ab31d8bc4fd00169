"""EuRoC MAV / ASL-format folders → :class:`Recording`.

Input: a folder containing ``mav0/imu0/data.csv`` (or ``imu0/data.csv``, or the ``data.csv`` itself)
with columns ``#timestamp [ns], w_RS_S_x, w_RS_S_y, w_RS_S_z [rad s^-1], a_RS_S_x, a_RS_S_y, a_RS_S_z
[m s^-2]`` (checked by name). Ground truth, the first that exists:

1. the ``ground_truth`` argument: an ASL ground-truth CSV or a TUM trajectory file
   (``t tx ty tz qx qy qz qw``, t in seconds, blank-separated, ``#`` comments);
2. ``mav0/state_groundtruth_estimate0/data.csv`` (``#timestamp, p_RS_R_xyz, q_RS_w, q_RS_x, q_RS_y,
   q_RS_z, ...``).

The reference is slerp-interpolated onto the IMU stamps inside the ground truth's time span only
(NaN outside it and across gaps longer than ``max_gap_s``).

Assumption (documented in the README): the ground-truth quaternion is the orientation of the IMU
frame with respect to a gravity-aligned world with z up. In EuRoC the ground truth describes the
body frame, which coincides with the IMU frame ``imu0`` (its ``T_BS`` is the identity), and the
reference frame ``R`` of ``state_groundtruth_estimate0`` is gravity aligned. For other ASL-format data
whose body frame differs from the IMU frame, pass ``imu_to_body`` (w, x, y, z; the IMU orientation in
the body frame): the reference becomes ``q_world_body ⊗ q_body_imu``.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from riann_ros import quaternion as quat
from riann_ros.datasets.csvfile import (
    InputError,
    check_stamps,
    float_columns,
    normalise_quats,
    parse_time_ns,
    read_table,
)
from riann_ros.recording import Recording

SOURCE = "EuRoC MAV / ASL format (Burri et al., IJRR 2016)"
IMU_COLS = ("timestamp", "w_RS_S_x", "w_RS_S_y", "w_RS_S_z", "a_RS_S_x", "a_RS_S_y", "a_RS_S_z")
GT_QUAT_COLS = ("q_RS_w", "q_RS_x", "q_RS_y", "q_RS_z")


def find_imu_csv(path: Path) -> Path:
    if path.is_file():
        return path
    for cand in (path / "mav0" / "imu0" / "data.csv", path / "imu0" / "data.csv", path / "data.csv"):
        if cand.is_file():
            return cand
    raise InputError(f"{path}: not an EuRoC/ASL folder (no mav0/imu0/data.csv)")


def is_euroc(path: Path) -> bool:
    return path.is_dir() and ((path / "mav0" / "imu0" / "data.csv").is_file() or (path / "imu0" / "data.csv").is_file())


def _bare(name: str) -> str:
    """``'#timestamp [ns]'`` → ``'timestamp'``."""
    return name.lstrip("#").split("[")[0].strip()


def _indices(header: list[str], names: tuple[str, ...], path: Path) -> list[int]:
    bare = [_bare(h) for h in header]
    missing = [n for n in names if n not in bare]
    if missing:
        raise InputError(
            f"{path}: line 1 header lacks column(s) {', '.join(missing)}; columns are: {', '.join(header)}"
        )
    return [bare.index(n) for n in names]


def read_ground_truth(path: str | os.PathLike[str]) -> tuple[np.ndarray, np.ndarray]:
    """Stamps (ns) and quaternions (w, x, y, z) from an ASL ground-truth CSV or a TUM file."""
    path = Path(path)
    header, rows, lines = read_table(path)
    bare = [_bare(h) for h in header]
    if "timestamp" in bare and all(c in bare for c in GT_QUAT_COLS):  # ASL csv
        ti = bare.index("timestamp")
        stamps = parse_time_ns([r[ti] for r in rows], "ns", str(path), lines)
        q = float_columns(rows, [bare.index(c) for c in GT_QUAT_COLS], path, lines, "quaternion")
    else:  # TUM: the "header" read_table found is the first data row unless it was a comment
        text_rows = rows
        text_lines = lines
        if _is_number_row(header):
            text_rows = [header, *rows]
            text_lines = [lines[0] - 1, *lines]
        if any(len(r) != 8 for r in text_rows) or not _is_number_row(text_rows[0]):
            raise InputError(
                f"{path}: neither an ASL ground-truth CSV (#timestamp, ..., q_RS_w, q_RS_x, q_RS_y, q_RS_z) "
                "nor a TUM file (t tx ty tz qx qy qz qw)"
            )
        stamps = parse_time_ns([r[0] for r in text_rows], "s", str(path), text_lines)
        xyzw = float_columns(text_rows, [4, 5, 6, 7], path, text_lines, "quaternion")
        q = xyzw[:, [3, 0, 1, 2]]
        lines = text_lines
    check_stamps(stamps, str(path), lines)
    return stamps, normalise_quats(q, path, lines)


def _is_number_row(cells: list[str]) -> bool:
    try:
        [float(c) for c in cells]
    except ValueError:
        return False
    return True


def interpolate(gt_ns: np.ndarray, gt_q: np.ndarray, stamps_ns: np.ndarray, max_gap_s: float = 0.1) -> np.ndarray:
    """Slerp ``gt_q`` onto ``stamps_ns``; NaN outside [gt_ns[0], gt_ns[-1]] and across gaps > max_gap_s."""
    out = np.full((len(stamps_ns), 4), np.nan)
    if len(gt_ns) == 0:
        return out
    inside = (stamps_ns >= gt_ns[0]) & (stamps_ns <= gt_ns[-1])
    s = stamps_ns[inside]
    hi = np.clip(np.searchsorted(gt_ns, s, side="left"), 0, len(gt_ns) - 1)
    lo = np.clip(hi - 1, 0, len(gt_ns) - 1)
    exact = gt_ns[hi] == s
    lo = np.where(exact, hi, lo)
    span = (gt_ns[hi] - gt_ns[lo]).astype(np.float64)
    frac = np.where(span > 0, (s - gt_ns[lo]) / np.where(span > 0, span, 1.0), 0.0)
    q = quat.slerp(gt_q[lo], gt_q[hi], frac)
    q = np.where((span * 1e-9 > max_gap_s)[:, None], np.nan, q)
    out[inside] = q
    return out


def read_euroc(
    path: str | os.PathLike[str],
    *,
    ground_truth: str | os.PathLike[str] | None = None,
    imu_to_body: np.ndarray | None = None,
    max_gap_s: float = 0.1,
    name: str | None = None,
    frame_id: str = "imu_link",
) -> Recording:
    """Read an EuRoC/ASL folder (see module docstring)."""
    path = Path(path)
    imu_csv = find_imu_csv(path)
    header, rows, lines = read_table(imu_csv)
    idx = _indices(header, IMU_COLS, imu_csv)
    stamps = parse_time_ns([r[idx[0]] for r in rows], "ns", str(imu_csv), lines)
    check_stamps(stamps, str(imu_csv), lines)
    gyr = float_columns(rows, idx[1:4], imu_csv, lines, "gyroscope")
    acc = float_columns(rows, idx[4:7], imu_csv, lines, "accelerometer")

    gt_path = Path(ground_truth) if ground_truth is not None else None
    if gt_path is None and path.is_dir():
        cand = path / "mav0" / "state_groundtruth_estimate0" / "data.csv"
        if not cand.is_file():
            cand = path / "state_groundtruth_estimate0" / "data.csv"
        gt_path = cand if cand.is_file() else None
    quat_ref = None
    meta = {"imu_file": str(imu_csv.relative_to(path)) if path.is_dir() else imu_csv.name}
    if gt_path is not None:
        if not gt_path.is_file():
            raise InputError(f"{gt_path}: ground-truth file not found")
        gt_ns, gt_q = read_ground_truth(gt_path)
        if imu_to_body is not None:
            gt_q = quat.multiply(gt_q, np.asarray(imu_to_body, dtype=float))
        quat_ref = interpolate(gt_ns, gt_q, stamps, max_gap_s)
        meta["ground_truth_file"] = gt_path.name
    seq = name or (path.name if path.is_dir() else imu_csv.parent.name)
    return Recording(
        stamps_ns=stamps,
        acc=acc,
        gyr=gyr,
        quat_ref=quat_ref,
        name=seq,
        dataset="euroc",
        source=SOURCE,
        frame_id=frame_id,
        meta=meta,
    )
