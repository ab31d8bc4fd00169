"""EuRoC MAV / ASL-format folders → :class:`Recording`.

Input: a folder containing ``mav0/imu0/data.csv`` (or ``imu0/data.csv``, or the ``data.csv`` itself)
with columns ``#timestamp [ns], w_RS_S_x, w_RS_S_y, w_RS_S_z [rad s^-1], a_RS_S_x, a_RS_S_y, a_RS_S_z
[m s^-2]`` (checked by name). Ground truth, the first that exists:

1. the ``ground_truth`` argument, one of
   * an ASL ground-truth CSV (``#timestamp, p_RS_R_xyz, q_RS_w, q_RS_x, q_RS_y, q_RS_z, ...``, ns);
   * an open_vins / vicon2gt-style CSV (``#time(ns),px,py,pz,qw,qx,qy,qz,...``): a time column named
     ``timestamp``, ``time`` or ``t`` (any case; a unit in the name such as ``(ns)`` or ``[s]`` is used,
     else ns) and columns ``qw, qx, qy, qz``, found by name in any order;
   * a TUM trajectory file (``t tx ty tz qx qy qz qw``, t in seconds, blank-separated, no header,
     ``#`` comments);
   * any CSV with a header, with ``gt_cols`` naming its time, qw, qx, qy, qz columns;
2. ``mav0/state_groundtruth_estimate0/data.csv`` (ASL, as above).

``gt_time_unit`` overrides the time unit of the ground-truth file. A ground truth that gives no IMU
sample a reference (time spans that do not overlap: usually a wrong time unit) is an error.

open_vins and vicon2gt write the JPL quaternion ``q_GtoI``; JPL ``q_GtoI`` and Hamilton ``q_ItoG`` (IMU →
gravity-aligned world, what this reader wants) have the same four numbers, so they are used as they are.

The reference is slerp-interpolated onto the IMU stamps inside the ground truth's time span only
(NaN outside it and across gaps longer than ``max_gap_s``).

Assumption (documented in docs/converter.md): the ground-truth quaternion is the orientation of the IMU
frame with respect to a gravity-aligned world with z up. In EuRoC the ground truth describes the
body frame, which coincides with the IMU frame ``imu0`` (its ``T_BS`` is the identity), and the
reference frame ``R`` of ``state_groundtruth_estimate0`` is gravity aligned. For other ASL-format data
whose body frame differs from the IMU frame, pass ``imu_to_body`` (w, x, y, z; the IMU orientation in
the body frame): the reference becomes ``q_world_body ⊗ q_body_imu``.
"""

from __future__ import annotations

import os
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from riann_ros import defaults
from riann_ros import quaternion as quat
from riann_ros.datasets.csvfile import (
    InputError,
    bare_name,
    check_stamps,
    float_columns,
    missing_columns_message,
    normalise_quats,
    parse_time_ns,
    read_table,
)
from riann_ros.recording import Recording

SOURCE = "EuRoC MAV / ASL format (Burri et al., IJRR 2016)"
IMU_COLS = ("timestamp", "w_RS_S_x", "w_RS_S_y", "w_RS_S_z", "a_RS_S_x", "a_RS_S_y", "a_RS_S_z")
GT_QUAT_COLS = ("q_RS_w", "q_RS_x", "q_RS_y", "q_RS_z")
# open_vins / vicon2gt ground truth (``#time(ns),px,py,pz,qw,qx,qy,qz,vx,...``): time column names tried in
# this order (case-insensitive, unit suffix removed) and the quaternion columns.
GT_TIME_NAMES = ("timestamp", "time", "t")
OV_QUAT_COLS = ("qw", "qx", "qy", "qz")


def find_imu_csv(path: Path) -> Path:
    if path.is_file():
        return path
    for cand in (path / "mav0" / "imu0" / "data.csv", path / "imu0" / "data.csv", path / "data.csv"):
        if cand.is_file():
            return cand
    raise InputError(f"{path}: not an EuRoC/ASL folder (no mav0/imu0/data.csv)")


def is_euroc(path: Path) -> bool:
    return path.is_dir() and ((path / "mav0" / "imu0" / "data.csv").is_file() or (path / "imu0" / "data.csv").is_file())


def _indices(header: list[str], names: tuple[str, ...], path: Path) -> list[int]:
    bare = [bare_name(h) for h in header]
    missing = [n for n in names if n not in bare]
    if missing:
        raise InputError(missing_columns_message(path, missing, header, "EuRoC IMU", None, taken=names))
    return [bare.index(n) for n in names]


def _unit_in_name(name: str) -> str | None:
    """The time unit written in a column name: ``'time(ns)'``, ``'#timestamp [ns]'`` → ``'ns'``; else None."""
    m = re.search(r"[\[(]\s*(s|ms|us|µs|ns)\s*[\])]", name)
    return m.group(1) if m else None


def _find_named(header: list[str], names: Sequence[str]) -> list[int | None]:
    """Index of each of ``names`` in ``header`` (as written, without ``#``, or without a unit suffix), or None."""
    out: list[int | None] = []
    for n in names:
        hits = [i for i, h in enumerate(header) if n in (h, h.lstrip("#").strip(), bare_name(h))]
        out.append(hits[0] if hits else None)
    return out


GT_OPTIONS = ("--gt-cols", "--gt-time-unit")  # the converter's options naming the columns and the time unit


def _named_layout(path: Path, header: list[str], cols: Sequence[str], cols_option: str = GT_OPTIONS[0],
                  kind: str = "ground-truth") -> list[int]:
    """Indices of the --gt-cols columns TIME, QW, QX, QY, QZ, else InputError with a hint (``kind``: what the file
    holds, for the message)."""
    found = _find_named(header, cols)
    missing = [c for c, i in zip(cols, found, strict=True) if i is None]
    if missing:
        raise InputError(
            missing_columns_message(path, missing, header, kind, cols_option, cols[0] in missing, cols)
        )
    return [i for i in found if i is not None]


def _auto_layout(path: Path, header: list[str], cols_option: str = GT_OPTIONS[0],
                 kind: str = "ground-truth") -> list[int] | None:
    """Indices of time, qw, qx, qy, qz in an ASL or open_vins-style header; None for a TUM file (no header).

    ASL: ``#timestamp, ..., q_RS_w, q_RS_x, q_RS_y, q_RS_z``. open_vins / vicon2gt:
    ``#time(ns),px,py,pz,qw,qx,qy,qz,...``: a time column named timestamp, time or t (any case, unit
    suffix allowed) and columns qw, qx, qy, qz, in any order.
    """
    bare = [bare_name(h) for h in header]
    if "timestamp" in bare and all(c in bare for c in GT_QUAT_COLS):
        return [bare.index(c) for c in ("timestamp", *GT_QUAT_COLS)]
    low = [b.lower() for b in bare]
    t = next((low.index(n) for n in GT_TIME_NAMES if n in low), None)
    if t is not None and all(q in low for q in OV_QUAT_COLS):
        return [t, *(low.index(q) for q in OV_QUAT_COLS)]
    if _is_number_row(header):
        return None
    missing = ([] if t is not None else ["time"]) + [q for q in OV_QUAT_COLS if q not in low]
    raise InputError(
        missing_columns_message(path, missing, header, kind, cols_option, t is None, OV_QUAT_COLS)
        + "; known layouts: ASL (#timestamp, ..., q_RS_w, q_RS_x, q_RS_y, q_RS_z), open_vins "
        "(#time(ns), ..., qw, qx, qy, qz) and TUM (t tx ty tz qx qy qz qw, no header); "
        f"{cols_option} TIME,QW,QX,QY,QZ names other columns"
    )


def _read_tum(path: Path, header: list[str], rows: list[list[str]], lines: list[int], time_unit: str):
    """A TUM file: the "header" read_table found is the first data row (a ``#`` comment header is skipped)."""
    rows = [header, *rows]
    lines = [lines[0] - 1, *lines]
    if any(len(r) != 8 for r in rows):
        raise InputError(
            f"{path}: neither an ASL CSV (#timestamp, ..., q_RS_w, q_RS_x, q_RS_y, q_RS_z), an "
            "open_vins one (#time(ns),px,py,pz,qw,qx,qy,qz) nor a TUM file (t tx ty tz qx qy qz qw)"
        )
    stamps = parse_time_ns([r[0] for r in rows], time_unit, str(path), lines)
    xyzw = float_columns(rows, [4, 5, 6, 7], path, lines, "quaternion")
    return stamps, xyzw[:, [3, 0, 1, 2]], lines


def read_ground_truth(
    path: str | os.PathLike[str], cols: Sequence[str] | None = None, time_unit: str | None = None,
    options: tuple[str, str] = GT_OPTIONS,
    kind: str = "ground-truth",
) -> tuple[np.ndarray, np.ndarray]:
    """Stamps (ns) and quaternions (w, x, y, z) from a ground-truth file.

    Layouts: ``cols`` (names of the time, qw, qx, qy, qz columns, any order in the file); else an ASL
    CSV (``#timestamp, ..., q_RS_w..z``), an open_vins-style CSV (``#time(ns),px,py,pz,qw,qx,qy,qz``,
    columns found by name) or a TUM file (``t tx ty tz qx qy qz qw``, no header). ``time_unit``: the unit
    of the time column; default: the unit in its name (``time(ns)``, ``timestamp [s]``), else ns for CSVs
    with a header and s for TUM files. ``options``: the command-line options that name the columns and the time
    unit, for the messages (the converter's ``--gt-cols``, ``--gt-time-unit``); ``kind``: what the file holds, for
    the messages (``ground-truth``, or ``estimate`` for riann-bag-eval's ``--estimate-file``).
    """
    path = Path(path)
    header, rows, lines = read_table(path)
    idx = _named_layout(path, header, cols, options[0], kind) if cols is not None else _auto_layout(
        path, header, options[0], kind)
    if idx is None:
        unit = time_unit or "s"
        stamps, q, lines = _read_tum(path, header, rows, lines, unit)
    else:
        unit = time_unit or _unit_in_name(header[idx[0]]) or "ns"
        stamps = parse_time_ns([r[idx[0]] for r in rows], unit, str(path), lines)
        q = float_columns(rows, idx[1:], path, lines, "quaternion")
    try:
        check_stamps(stamps, str(path), lines)
    except InputError as e:  # e.g. seconds read as ns: 5 ms steps round to the same ns
        raise InputError(f"{e} (time read in {unit}; if that is wrong, use {options[1]})") from None
    return stamps, normalise_quats(q, path, lines, "estimate quaternion" if kind == "estimate" else
                                   "reference quaternion")


def _is_number_row(cells: list[str]) -> bool:
    try:
        [float(c) for c in cells]
    except ValueError:
        return False
    return True


def _span(ns: np.ndarray) -> str:
    return f"{ns[0] * 1e-9:.3f} s – {ns[-1] * 1e-9:.3f} s"


def _check_overlap(gt_path: Path, gt_ns: np.ndarray, stamps: np.ndarray, quat_ref: np.ndarray, max_gap_s: float):
    """InputError when no IMU sample got a reference: the time spans do not overlap, or every one is in a gap."""
    if np.isfinite(quat_ref).all(axis=1).any():
        return
    if stamps[-1] < gt_ns[0] or stamps[0] > gt_ns[-1]:
        raise InputError(
            f"{gt_path}: the ground truth ({_span(gt_ns)}) does not overlap the IMU data ({_span(stamps)}), so no "
            "sample would have a reference; is its time unit right (--gt-time-unit)?"
        )
    raise InputError(
        f"{gt_path}: every IMU sample falls in a ground-truth gap longer than --max-gap {max_gap_s:g} s "
        f"(ground truth: {len(gt_ns)} poses, {_span(gt_ns)})"
    )


def interpolate(gt_ns: np.ndarray, gt_q: np.ndarray, stamps_ns: np.ndarray,
                max_gap_s: float = defaults.MAX_GAP_S) -> np.ndarray:
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
    gt_cols: Sequence[str] | None = None,
    gt_time_unit: str | None = None,
    imu_to_body: np.ndarray | None = None,
    max_gap_s: float = defaults.MAX_GAP_S,
    name: str | None = None,
    frame_id: str = defaults.IMU_FRAME,
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
        gt_ns, gt_q = read_ground_truth(gt_path, gt_cols, gt_time_unit)
        if imu_to_body is not None:
            gt_q = quat.multiply(gt_q, np.asarray(imu_to_body, dtype=float))
        quat_ref = interpolate(gt_ns, gt_q, stamps, max_gap_s)
        _check_overlap(gt_path, gt_ns, stamps, quat_ref, max_gap_s)
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
