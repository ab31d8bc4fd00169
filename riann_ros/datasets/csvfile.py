"""Generic CSV IMU files → :class:`Recording`.

Format: one header row with column names, then one row per sample. Before the header, blank lines
and ``#`` comment lines are skipped; a ``#`` line that contains ``,``, ``;`` or a tab which the first data row
contains too is the header, with the ``#`` stripped (as in EuRoC's ``#timestamp [ns],...``), while a ``#``
line over blank-separated rows is a comment whatever it holds (a TUM file's). After the header, blank
and ``#`` lines are skipped. The delimiter is detected from the header (``,``, ``;``, tab, or blanks).

Columns (names and units by option; defaults in brackets):

* time [``t``], unit ``s`` | ``ms`` | ``us`` | ``ns`` [``s``]; parsed exactly (decimal → integer ns);
  must be strictly increasing;
* accelerometer [``acc_x,acc_y,acc_z``], unit ``m/s2`` | ``g`` [``m/s2``] (1 g = 9.80665 m/s²);
* gyroscope [``gyr_x,gyr_y,gyr_z``], unit ``rad/s`` | ``deg/s`` | ``mrad/s`` | ``mdeg/s`` [``rad/s``];
* optional reference quaternion [``qw,qx,qy,qz``], listed in the order given by ``quat_order``
  (``wxyz`` | ``xyzw``) [``wxyz``], sensor → world (z up); empty or NaN cells mark a missing reference
  (NaN row); non-empty rows are normalised (norm must be within 10 % of 1);
* optional score mask [``scored``]: 1/0, true/false;
* optional magnetometer [``mag_x,mag_y,mag_z``], unit ``uT`` | ``nT`` | ``mT`` | ``G`` | ``T`` [``uT``],
  stored in tesla; empty or NaN cells mark a sample without a field reading (a slower magnetometer).

The optional columns are used when all their default names are present; when given explicitly
they are required. IMU cells must be finite numbers. Errors name the file and line.
"""

from __future__ import annotations

import difflib
import itertools
import os
import re
from collections.abc import Sequence
from decimal import Decimal, InvalidOperation
from pathlib import Path

import numpy as np

from riann_ros import defaults
from riann_ros.constants import DEG, GRAVITY
from riann_ros.recording import Recording

TIME_UNITS = {"s": 10**9, "ms": 10**6, "us": 10**3, "µs": 10**3, "ns": 1}
ACC_UNITS = {"m/s2": 1.0, "m/s^2": 1.0, "m/s²": 1.0, "g": GRAVITY}
GYR_UNITS = {"rad/s": 1.0, "deg/s": DEG, "dps": DEG, "mrad/s": 1e-3, "mdeg/s": 1e-3 * DEG, "mdps": 1e-3 * DEG}
MAG_UNITS = {"uT": 1e-6, "µT": 1e-6, "nT": 1e-9, "mT": 1e-3, "G": 1e-4, "gauss": 1e-4, "T": 1.0}
QUAT_ORDERS = ("wxyz", "xyzw")
DEFAULT_TIME = "t"
DEFAULT_ACC = ("acc_x", "acc_y", "acc_z")
DEFAULT_GYR = ("gyr_x", "gyr_y", "gyr_z")
DEFAULT_QUAT = ("qw", "qx", "qy", "qz")
DEFAULT_MASK = "scored"
DEFAULT_MAG = ("mag_x", "mag_y", "mag_z")
_TRUE = {"1", "true", "yes", "y", "t", "1.0"}
_FALSE = {"0", "false", "no", "n", "f", "0.0"}


class InputError(ValueError):
    """Bad input data; the message names the file and the line or sample index."""


def unit_factor(kind: str, unit: str, table: dict) -> float | int:
    if unit not in table:
        raise InputError(f"unknown {kind} unit {unit!r}; expected one of {', '.join(table)}")
    return table[unit]


def parse_time_ns(values: Sequence[str], unit: str, where: str, lines: Sequence[int]) -> np.ndarray:
    """Exact conversion of decimal time strings in ``unit`` to int64 nanoseconds."""
    scale = unit_factor("time", unit, TIME_UNITS)
    out = np.empty(len(values), dtype=np.int64)
    for i, v in enumerate(values):
        try:
            if v.isdigit():
                out[i] = int(v) * scale
            else:
                d = Decimal(v) * Decimal(scale)
                if not d.is_finite():
                    raise InvalidOperation
                out[i] = int(d.to_integral_value())
        except (InvalidOperation, ValueError, OverflowError):
            raise InputError(f"{where}:{lines[i]}: bad time value {v!r}") from None
    return out


def check_stamps(stamps: np.ndarray, where: str, lines: Sequence[int] | None = None) -> None:
    """Strictly increasing stamps, else InputError naming the line (or sample index)."""
    d = np.diff(stamps)
    bad = np.flatnonzero(d <= 0)
    if len(bad):
        i = int(bad[0]) + 1
        loc = f"{where}:{lines[i]}" if lines is not None else f"{where}: sample {i}"
        what = "duplicated" if d[bad[0]] == 0 else "non-monotonic (goes back in time)"
        raise InputError(f"{loc}: {what} time stamp {int(stamps[i])} ns after {int(stamps[i - 1])} ns")


_DELIMITERS = (",", ";", "\t")


def _comment_line(lines: list[str], k: int) -> bool:
    """Whether line ``k`` is a ``#`` comment rather than a ``#`` header (ASL's ``#timestamp, …``): a header has a
    delimiter that the first data line after it has too; a ``#`` line over a blank-separated table (a TUM file's
    ``# t x y z … (…, …)``) is a comment whatever punctuation it holds."""
    line = lines[k].lstrip()
    if not line.startswith("#"):
        return False
    data = next((x for x in itertools.islice(lines, k + 1, None) if x.strip() and not x.lstrip().startswith("#")), "")
    return not any(d in line and d in data for d in _DELIMITERS)


def read_table(path: Path, delimiter: str | None = None) -> tuple[list[str], list[list[str]], list[int]]:
    """Header names, rows of cell strings and their 1-based line numbers."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as e:
        raise InputError(f"{path}: not a text file ({e})") from None
    lines = text.splitlines()
    k = 0
    while k < len(lines) and (not lines[k].strip() or _comment_line(lines, k)):
        k += 1
    if k >= len(lines):
        raise InputError(f"{path}: empty file (no header row)")
    header_line = lines[k].strip().lstrip("#").strip()
    if delimiter is None:
        delimiter = next((d for d in _DELIMITERS if d in header_line), None)
    split = (lambda s: s.split()) if delimiter is None else (lambda s: [c.strip() for c in s.split(delimiter)])
    header = [h.strip() for h in split(header_line)]
    rows, numbers = [], []
    for j in range(k + 1, len(lines)):
        s = lines[j].strip()
        if not s or s.startswith("#"):
            continue
        cells = split(s)
        if len(cells) != len(header):
            raise InputError(f"{path}:{j + 1}: {len(cells)} cells, the header has {len(header)} columns")
        rows.append(cells)
        numbers.append(j + 1)
    if not rows:
        raise InputError(f"{path}: no data rows after the header (line {k + 1})")
    return header, rows, numbers


# The riann-bag-convert option naming each kind of column, for "missing column" messages.
COLUMN_FLAGS = {
    "time": "--time-col",
    "accelerometer": "--acc-cols",
    "gyroscope": "--gyr-cols",
    "quaternion": "--quat-cols",
    "score mask": "--mask-col",
}
_TIME_LIKE = {"t", "time", "times", "timestamp", "timestamps", "stamp", "sec", "secs", "seconds"}


def bare_name(name: str) -> str:
    """A column name without ``#``, a unit in brackets or parentheses and blanks: ``'#time(ns)'`` → ``'time'``."""
    return re.sub(r"\s*[\[(].*$", "", name.strip().lstrip("#")).strip()


def _key(name: str) -> str:
    return re.sub(r"[\W_]", "", bare_name(name)).lower()


def did_you_mean(name: str, header: Sequence[str], time_like: bool = False, taken: Sequence[str] = ()) -> list[str]:
    """Header names that ``name`` was probably meant to be: equal up to case, punctuation and a unit suffix,
    else close spellings (difflib), else, for a time column, the header's time-like names; never the
    names in ``taken`` (the other columns asked for: ``gyr_y`` is no hint for a missing ``gyr_z``)."""
    free = [h for h in header if h != name and h not in taken]
    close = [h for h in free if _key(h) == _key(name)]
    if not close:
        close = difflib.get_close_matches(name, free, n=2, cutoff=0.75)
    if not close and time_like:
        close = [h for h in free if _key(h) in _TIME_LIKE]
    return close


def missing_columns_message(
    path: Path,
    missing: Sequence[str],
    header: Sequence[str],
    what: str,
    flag: str | None,
    time_like: bool = False,
    taken: Sequence[str] = (),
) -> str:
    """``"<path>: no <what> column 'x' (did you mean 'X'? use <flag> to name it; columns: ...)"``."""
    names = ", ".join(repr(m) for m in missing)
    close: list[str] = []
    for m in missing:
        close += [c for c in did_you_mean(m, header, time_like, taken) if c not in close]
    hint = f"did you mean {', '.join(repr(c) for c in close)}? " if close else ""
    use = f"use {flag} to name {'it' if flag in ('--time-col', '--mask-col') else 'them'}; " if flag else ""
    plural = "s" if len(missing) > 1 else ""
    return f"{path}: no {what} column{plural} {names} ({hint}{use}columns: {', '.join(header)})"


def column_index(header: list[str], names: Sequence[str], path: Path, what: str) -> list[int]:
    """Indices of ``names`` in ``header``, else InputError naming the missing columns and the flag that names them."""
    missing = [n for n in names if n not in header]
    if missing:
        flag = COLUMN_FLAGS.get(what)
        raise InputError(missing_columns_message(path, missing, header, what, flag, what == "time", names))
    return [header.index(n) for n in names]


def float_columns(
    rows: list[list[str]], idx: list[int], path: Path, lines: list[int], what: str, allow_nan: bool = False
) -> np.ndarray:
    out = np.empty((len(rows), len(idx)))
    for r, cells in enumerate(rows):
        for c, i in enumerate(idx):
            v = cells[i]
            try:
                out[r, c] = float(v) if v != "" else np.nan
            except ValueError:
                raise InputError(f"{path}:{lines[r]}: {what} value {v!r} is not a number") from None
    if not allow_nan:
        bad = ~np.isfinite(out).all(axis=1)
        if bad.any():
            r = int(np.flatnonzero(bad)[0])
            raise InputError(f"{path}:{lines[r]}: NaN/missing {what} value (row {r}, sample index {r})")
    return out


def normalise_quats(q: np.ndarray, path: Path, lines: Sequence[int], what: str = "reference quaternion") -> np.ndarray:
    """Normalise finite rows (NaN where any component is missing); reject non-unit quaternions (``what``: the
    quaternions' name in the message). A norm too large for a float is ``inf`` in the message, without a numpy
    warning."""
    ok = np.isfinite(q).all(axis=1)
    q = np.where(ok[:, None], q, np.nan)
    with np.errstate(over="ignore", invalid="ignore"):
        big = np.max(np.abs(q), axis=1)  # the norm of the row scaled to 1 at most, scaled back: no overflow
        norm = big * np.linalg.norm(q / np.where(big > 0.0, big, 1.0)[:, None], axis=1)
    bad = ok & (np.abs(norm - 1.0) > 0.1)
    if bad.any():
        r = int(np.flatnonzero(bad)[0])
        raise InputError(f"{path}:{lines[r]}: {what} norm {norm[r]:.3g} is not ≈ 1")
    return q / norm[:, None]


def _check_options(
    time_unit: str,
    acc_unit: str,
    gyr_unit: str,
    quat_order: str,
    acc_cols: Sequence[str],
    gyr_cols: Sequence[str],
    quat_cols: Sequence[str] | None,
) -> tuple[float | int, float | int]:
    """Validate units, quaternion order and column counts before reading; the acc and gyr scale factors."""
    unit_factor("time", time_unit, TIME_UNITS)
    a_scale = unit_factor("accelerometer", acc_unit, ACC_UNITS)
    g_scale = unit_factor("gyroscope", gyr_unit, GYR_UNITS)
    if quat_order not in QUAT_ORDERS:
        raise InputError(f"unknown quaternion order {quat_order!r}; expected wxyz or xyzw")
    for what, cols in (("accelerometer", acc_cols), ("gyroscope", gyr_cols)):
        if len(cols) != 3:
            raise InputError(f"{what} needs 3 column names, got {len(cols)}: {', '.join(cols)}")
    if quat_cols is not None and len(quat_cols) != 4:
        raise InputError(f"quaternion needs 4 column names, got {len(quat_cols)}: {', '.join(quat_cols)}")
    return a_scale, g_scale


def _optional_columns(
    header: list[str], quat_cols: Sequence[str] | None, quat_order: str, mask_col: str | None
) -> tuple[Sequence[str] | None, str | None]:
    """The quaternion and score-mask columns to read: those given, else the defaults when all present in ``header``."""
    if quat_cols is None:
        default = DEFAULT_QUAT if quat_order == "wxyz" else (*DEFAULT_QUAT[1:], DEFAULT_QUAT[0])
        quat_cols = default if all(c in header for c in default) else None
    if mask_col is None and DEFAULT_MASK in header:
        mask_col = DEFAULT_MASK
    return quat_cols, mask_col


class _CsvTable:
    """The header, cell rows and line numbers of one CSV file, and the column parsers (errors name the line)."""

    def __init__(self, path: Path, delimiter: str | None) -> None:
        self.path = path
        self.header, self.rows, self.lines = read_table(path, delimiter)
        dup = sorted({h for h in self.header if self.header.count(h) > 1})
        if dup:
            raise InputError(f"{path}: duplicated column name(s) {', '.join(dup)} in the header")

    def columns(self, names: Sequence[str], what: str) -> list[int]:
        return column_index(self.header, list(names), self.path, what)

    def floats(self, idx: list[int], what: str, allow_nan: bool = False) -> np.ndarray:
        return float_columns(self.rows, idx, self.path, self.lines, what, allow_nan=allow_nan)

    def stamps(self, ti: int, time_unit: str) -> np.ndarray:
        """Exact int64 ns stamps of column ``ti``, checked strictly increasing."""
        stamps = parse_time_ns([r[ti] for r in self.rows], time_unit, str(self.path), self.lines)
        check_stamps(stamps, str(self.path), self.lines)
        return stamps

    def quaternions(self, quat_cols: Sequence[str], quat_order: str) -> np.ndarray:
        """Normalised w, x, y, z reference rows (NaN where a cell is empty or NaN)."""
        qi = self.columns(quat_cols, "quaternion")
        q = self.floats(qi, "quaternion", allow_nan=True)
        if quat_order == "xyzw":
            q = q[:, [3, 0, 1, 2]]
        return normalise_quats(q, self.path, self.lines)

    def score_mask(self, mask_col: str) -> np.ndarray:
        """The score mask column as bools (1/0, true/false, yes/no, ...)."""
        (mi,) = self.columns([mask_col], "score mask")
        mask = np.empty(len(self.rows), dtype=bool)
        for r, cells in enumerate(self.rows):
            v = cells[mi].strip().lower()
            if v in _TRUE:
                mask[r] = True
            elif v in _FALSE:
                mask[r] = False
            else:
                raise InputError(f"{self.path}:{self.lines[r]}: score mask value {cells[mi]!r} is not 1/0/true/false")
        return mask


def read_csv(
    path: str | os.PathLike[str],
    *,
    time_col: str = DEFAULT_TIME,
    time_unit: str = "s",
    acc_cols: Sequence[str] = DEFAULT_ACC,
    acc_unit: str = "m/s2",
    gyr_cols: Sequence[str] = DEFAULT_GYR,
    gyr_unit: str = "rad/s",
    quat_cols: Sequence[str] | None = None,
    quat_order: str = "wxyz",
    mask_col: str | None = None,
    delimiter: str | None = None,
    name: str | None = None,
    frame_id: str = defaults.IMU_FRAME,
    mag_cols: Sequence[str] | None = None,
    mag_unit: str = "uT",
) -> Recording:
    """Read a generic CSV file (format in the module docstring)."""
    path = Path(path)
    a_scale, g_scale = _check_options(time_unit, acc_unit, gyr_unit, quat_order, acc_cols, gyr_cols, quat_cols)
    m_scale = unit_factor("magnetometer", mag_unit, MAG_UNITS)
    if mag_cols is not None and len(mag_cols) != 3:
        raise InputError(f"magnetometer needs 3 column names, got {len(mag_cols)}: {', '.join(mag_cols)}")
    table = _CsvTable(path, delimiter)
    (ti,) = table.columns([time_col], "time")
    ai = table.columns(acc_cols, "accelerometer")
    gi = table.columns(gyr_cols, "gyroscope")
    quat_cols, mask_col = _optional_columns(table.header, quat_cols, quat_order, mask_col)
    if mag_cols is None and all(c in table.header for c in DEFAULT_MAG):
        mag_cols = DEFAULT_MAG

    stamps = table.stamps(ti, time_unit)
    acc = table.floats(ai, "accelerometer") * a_scale
    gyr = table.floats(gi, "gyroscope") * g_scale
    quat = table.quaternions(quat_cols, quat_order) if quat_cols is not None else None
    mask = table.score_mask(mask_col) if mask_col is not None else None
    mag = None
    if mag_cols is not None:
        mag = table.floats(table.columns(mag_cols, "magnetometer"), "magnetometer", allow_nan=True) * m_scale
    meta = {"file": path.name, "time_unit": time_unit, "acc_unit": acc_unit, "gyr_unit": gyr_unit}
    if mag is not None:
        meta["mag_unit"] = mag_unit
    return Recording(
        stamps_ns=stamps,
        acc=acc,
        gyr=gyr,
        quat_ref=quat,
        score_mask=mask,  # type: ignore[arg-type]  # None: all scored
        name=name or path.stem,
        dataset="csv",
        source=f"CSV file {path.name}",
        frame_id=frame_id,
        meta=meta,
        mag=mag,
    )
