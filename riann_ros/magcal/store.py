"""The saved calibration: a YAML file in the node's own parameter names (ROS-free).

::

    # magnetometer calibration (riann_ros.magcal); load it with the node parameter mag_calibration_file
    mag_hard_iron: [2.0e-05, 0.0, -1.0e-05]        # T, sensor frame
    mag_soft_iron: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]  # row-major: m = S (m_raw - hard_iron)
    mag_calibration:
      format: riann_ros.magcal/1
      state: calibrated            # uncalibrated / converging / calibrated
      windows: 412                 # windows of rotation the estimate holds
      converged_after_s: 48.2      # s after the saving run's first sample it was first called calibrated (or null)
      soft_iron_model: symmetric
      covariance: [...]            # 144 numbers: 12x12 row-major over (soft iron row-major, hard iron in T)

:func:`save_calibration` writes atomically (a temporary file ``.<name>.<random>.tmp`` in the same folder, flushed
and synced, then renamed over the target): a crash leaves the old file or the new one, never half of one, and at
worst the temporary file, which :func:`remove_temporaries` removes (the node does at its next start). The new file
keeps the mode of the one it replaces (a new one gets the process's umask). It only writes the path it is given,
never a calibration :mod:`~riann_ros.magcal.validate` refuses, and refuses to replace a file there that is not a
calibration file (a parameter file given by mistake, say) unless told to, and anything but a regular file always.

:func:`load_calibration` refuses a file that is not one, or whose numbers are not a usable calibration
(:func:`riann_ros.magcal.validate.refusals`), with a :class:`CalibrationFileError` naming the file and the problem;
the node then runs on its parameters. Reading is bounded in size and time: only a regular file is opened (a FIFO, a
device such as ``/dev/zero``, a folder or a socket is refused from its ``stat``, and the open itself cannot block),
and only up to :data:`MAX_FILE_BYTES`.

:func:`less_certain` says whether a calibration would downgrade the one in a file (the node's save service keeps
the file then, unless forced).
"""

from __future__ import annotations

import math
import os
import secrets
import stat
from pathlib import Path
from typing import Any

import yaml

from riann_ros.magcal.records import SOFT_IRON_MODELS, STATES, UT, MagCalibration
from riann_ros.magcal.validate import calibration_refusals

FORMAT = "riann_ros.magcal/1"
SECTION = "mag_calibration"
#: bytes; the largest file read as a calibration. A calibration file is about 4 KB (156 numbers and a header); 16
#: times that leaves room for comments, and YAML of this size parses in about 0.05 s (libyaml; 0.6 s without it).
MAX_FILE_BYTES = 64 * 1024
_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # libyaml's parser where PyYAML was built with it
#: the deepest YAML nesting read: the format nests three deep (the file, its section, the covariance list)
MAX_DEPTH = 8
HEADER = ("# magnetometer calibration (riann_ros.magcal); load it with the node parameter mag_calibration_file\n"
          "# mag_hard_iron: T, sensor frame; mag_soft_iron: row-major S, the field used is S (m_raw - mag_hard_iron)\n"
          "# covariance: 12x12 row-major over (soft iron row-major, hard iron in T)\n")


class CalibrationFileError(ValueError):
    """A calibration file that cannot be read, is not one, or holds an unusable calibration (message: which file,
    what is wrong)."""


def to_yaml(cal: MagCalibration) -> str:
    """The file's text for ``cal``."""
    doc = {
        "mag_hard_iron": [float(v) for v in cal.hard_iron_t],
        "mag_soft_iron": [float(v) for v in cal.soft_iron],
        SECTION: {"format": FORMAT, "state": cal.state, "windows": int(cal.windows),
                  "converged_after_s": cal.converged_after_s, "soft_iron_model": cal.soft_iron_model,
                  "covariance": [float(v) for v in cal.covariance]},
    }
    return HEADER + yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=10_000)


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "not a regular file"


def read_text(path: str | os.PathLike[str]) -> str:
    """The text of the file at ``path``, read bounded in size and time (module docstring); CalibrationFileError
    naming the file when it is not a regular file, is over :data:`MAX_FILE_BYTES`, cannot be read or is not
    UTF-8."""
    where = str(path)
    try:
        st = os.stat(path)
        if not stat.S_ISREG(st.st_mode):
            raise CalibrationFileError(f"{where}: is {_kind(st.st_mode)}, not a calibration file (not read)")
        if st.st_size > MAX_FILE_BYTES:
            raise CalibrationFileError(f"{where}: is {st.st_size} bytes, over the {MAX_FILE_BYTES // 1024} KiB a "
                                       "calibration file can be (not read)")
        # non-blocking: a FIFO swapped in after the stat opens at once, and is refused by the fstat below
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC | getattr(os, "O_NOCTTY", 0))
        try:
            mode = os.fstat(fd).st_mode
            if not stat.S_ISREG(mode):
                raise CalibrationFileError(f"{where}: is {_kind(mode)}, not a calibration file (not read)")
            chunks, size = [], 0
            while size <= MAX_FILE_BYTES and (chunk := os.read(fd, MAX_FILE_BYTES + 1 - size)):
                chunks.append(chunk)
                size += len(chunk)
        finally:
            os.close(fd)
    except OSError as e:
        raise CalibrationFileError(f"{where}: cannot be read ({e.strerror or e})") from None
    if size > MAX_FILE_BYTES:
        raise CalibrationFileError(f"{where}: is over the {MAX_FILE_BYTES // 1024} KiB a calibration file can be")
    try:
        return b"".join(chunks).decode("utf-8")
    except UnicodeDecodeError:
        raise CalibrationFileError(f"{where}: is not valid YAML (not UTF-8 text)") from None


def _depth(text: str) -> int:
    """How deep the YAML ``text`` nests, counted on its event stream (iterative: no recursion) up to one past
    :data:`MAX_DEPTH`."""
    depth = deepest = 0
    for event in yaml.parse(text, Loader=_LOADER):
        if isinstance(event, yaml.CollectionStartEvent):
            depth += 1
            deepest = max(deepest, depth)
            if depth > MAX_DEPTH:
                break
        elif isinstance(event, yaml.CollectionEndEvent):
            depth -= 1
    return deepest


def _parse(path: str | os.PathLike[str]) -> Any:
    text = read_text(path)
    try:
        if _depth(text) > MAX_DEPTH:  # (libyaml's composer recurses in C: a deep enough nesting crashes it)
            raise CalibrationFileError(f"{path}: not a magnetometer calibration file (YAML nested over {MAX_DEPTH} "
                                       "deep)")
        return yaml.load(text, Loader=_LOADER)  # a safe loader (no Python objects)
    except (yaml.YAMLError, RecursionError) as e:
        raise CalibrationFileError(f"{path}: is not valid YAML ({str(e).splitlines()[0]})") from None


def is_calibration_file(path: Path) -> bool:
    """Whether ``path`` holds a calibration file of this format (False for anything unreadable, or not a regular
    file)."""
    try:
        doc = _parse(path)
    except CalibrationFileError:
        return False
    return isinstance(doc, dict) and isinstance(doc.get(SECTION), dict) and doc[SECTION].get("format") == FORMAT


def _temporary(target: Path, folder: Path, mode: int | None) -> tuple[int, Path]:
    """A new temporary file beside ``target`` (open for writing): created with 0o666 less the umask, then given
    ``mode`` (the replaced file's) when there is one."""
    while True:
        tmp = folder / f".{target.name}.{secrets.token_hex(4)}.tmp"
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o666)
        except FileExistsError:
            continue
        try:
            if mode is not None:
                os.fchmod(fd, mode)
        except OSError:
            os.close(fd)
            tmp.unlink(missing_ok=True)
            raise
        return fd, tmp


def remove_temporaries(path: str | os.PathLike[str]) -> list[Path]:
    """Remove the temporary files a save of ``path`` left when it was cut off (``.<name>.<random>.tmp`` beside it;
    regular files only); returns those removed."""
    target = Path(path)
    folder = target.parent if str(target.parent) else Path(".")
    prefix = f".{target.name}."
    removed = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return []
    for e in entries:
        if e.name.startswith(prefix) and e.name.endswith(".tmp") and e.is_file(follow_symlinks=False):
            try:
                os.unlink(e.path)
            except OSError:
                continue
            removed.append(Path(e.path))
    return removed


def save_calibration(path: str | os.PathLike[str], cal: MagCalibration, replace_other: bool = False) -> Path:
    """Write ``cal`` to ``path`` atomically (module docstring). A calibration that validation refuses is not written;
    an existing file there is replaced only if it is a calibration file, or ``replace_other`` (and never when it is
    not a regular file); otherwise :class:`CalibrationFileError`. Returns the path written."""
    target = Path(path)
    reasons = calibration_refusals(cal)
    if reasons:
        raise CalibrationFileError(f"{target}: the calibration is refused: {'; '.join(reasons)}")
    try:
        st: os.stat_result | None = os.stat(target)
    except FileNotFoundError:
        st = None
    if st is not None and not stat.S_ISREG(st.st_mode):
        raise CalibrationFileError(f"{target}: is {_kind(st.st_mode)}, not a calibration file; not replaced")
    if st is not None and not replace_other and not is_calibration_file(target):
        raise CalibrationFileError(f"{target}: exists and is not a magnetometer calibration file; not replaced")
    text = to_yaml(cal)
    folder = target.parent if str(target.parent) else Path(".")
    fd, tmp = _temporary(target, folder, None if st is None else stat.S_IMODE(st.st_mode))
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    try:  # the rename itself survives a power loss once the folder is synced
        dfd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)
    except OSError:
        pass
    return target


def _numbers(doc: dict[str, Any], key: str, n: int, where: str) -> tuple[float, ...]:
    v = doc.get(key)
    if not isinstance(v, list) or len(v) != n:
        raise CalibrationFileError(f"{where}: {key} must be a list of {n} numbers")
    try:
        out = tuple(float(x) for x in v)
    except (TypeError, ValueError):
        raise CalibrationFileError(f"{where}: {key} must be a list of {n} numbers") from None
    if not all(math.isfinite(x) for x in out) or any(isinstance(x, bool) for x in v):
        raise CalibrationFileError(f"{where}: {key} must hold finite numbers")
    return out


def load_calibration(path: str | os.PathLike[str]) -> MagCalibration:
    """Read a calibration file (module docstring); :class:`CalibrationFileError` when it cannot be used."""
    where = str(path)
    doc = _parse(path)
    if not isinstance(doc, dict) or not isinstance(doc.get(SECTION), dict):
        raise CalibrationFileError(f"{where}: not a magnetometer calibration file (no {SECTION} section)")
    sec = doc[SECTION]
    if sec.get("format") != FORMAT:
        raise CalibrationFileError(f"{where}: format {sec.get('format')!r} is not {FORMAT!r}")
    hard = _numbers(doc, "mag_hard_iron", 3, where)
    soft = _numbers(doc, "mag_soft_iron", 9, where)
    cov = _numbers(sec, "covariance", 144, where)
    state, model, windows, conv = sec.get("state"), sec.get("soft_iron_model"), sec.get("windows"), \
        sec.get("converged_after_s")
    if state not in STATES:
        raise CalibrationFileError(f"{where}: state must be one of {', '.join(STATES)}, got {state!r}")
    if model not in SOFT_IRON_MODELS:
        raise CalibrationFileError(f"{where}: soft_iron_model must be one of {', '.join(SOFT_IRON_MODELS)}")
    if not isinstance(windows, int) or isinstance(windows, bool) or windows < 0:
        raise CalibrationFileError(f"{where}: windows must be a whole number >= 0")
    if conv is not None and (isinstance(conv, bool) or not isinstance(conv, int | float) or not conv >= 0.0):
        raise CalibrationFileError(f"{where}: converged_after_s must be a number >= 0 or null")
    cal = MagCalibration(hard_iron_t=hard, soft_iron=soft, covariance=cov, state=state,  # type: ignore[arg-type]
                         windows=windows, converged_after_s=None if conv is None else float(conv),
                         soft_iron_model=model)
    reasons = calibration_refusals(cal)
    if reasons:
        raise CalibrationFileError(f"{where}: {'; '.join(reasons)}")
    return cal


def _hard_iron_var(cal: MagCalibration) -> float:
    """T²; the hard iron's total variance (the trace of its 3×3 covariance)."""
    return sum(v * v for v in cal.hard_iron_sd_t)


def less_certain(new: MagCalibration, old: MagCalibration) -> str | None:
    """Why ``new`` would downgrade ``old`` (a file's), or None when it would not: its state ranks lower
    (uncalibrated < converging < calibrated), or at the same state its hard iron is less certain (a larger total
    variance)."""
    rank_new, rank_old = STATES.index(new.state), STATES.index(old.state)
    if rank_new != rank_old:
        return None if rank_new > rank_old else f"the file's calibration is {old.state}, the current one {new.state}"
    if _hard_iron_var(new) > _hard_iron_var(old):
        return (f"the file's hard iron is known to ±{math.sqrt(_hard_iron_var(old)) / UT:.2f} µT, the current one's "
                f"to ±{math.sqrt(_hard_iron_var(new)) / UT:.2f} µT (both {new.state})")
    return None
