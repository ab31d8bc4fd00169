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

:func:`save_calibration` writes atomically (a temporary file in the same folder, flushed and synced, then renamed
over the target): a crash leaves the old file or the new one, never half of one. It only writes the path it is
given, and refuses to replace a file there that is not a calibration file (a parameter file given by mistake, say)
unless told to. :func:`load_calibration` refuses a file that is not one, or whose numbers are not a usable
calibration, with a :class:`CalibrationFileError` naming the file and the problem; the node then runs on its
parameters.
"""

from __future__ import annotations

import math
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from riann_ros.magcal.records import SOFT_IRON_MODELS, STATES, USABLE_MAX_T, MagCalibration

FORMAT = "riann_ros.magcal/1"
SECTION = "mag_calibration"
MAX_CONDITION = 1e3  # a soft-iron matrix more ill-conditioned than this is not a calibration (an axis ~lost)
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


def is_calibration_file(path: Path) -> bool:
    """Whether ``path`` holds a calibration file of this format (False for anything unreadable)."""
    try:
        doc = yaml.safe_load(path.read_text())
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        return False
    return isinstance(doc, dict) and isinstance(doc.get(SECTION), dict) and doc[SECTION].get("format") == FORMAT


def save_calibration(path: str | os.PathLike[str], cal: MagCalibration, replace_other: bool = False) -> Path:
    """Write ``cal`` to ``path`` atomically (module docstring). An existing file there is replaced only if it is a
    calibration file, or ``replace_other``; otherwise :class:`CalibrationFileError`. Returns the path written."""
    target = Path(path)
    if target.is_dir():
        raise CalibrationFileError(f"{target}: is a folder, not a calibration file")
    if target.exists() and not replace_other and not is_calibration_file(target):
        raise CalibrationFileError(f"{target}: exists and is not a magnetometer calibration file; not replaced")
    text = to_yaml(cal)
    folder = target.parent if str(target.parent) else Path(".")
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=folder)
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
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


def _check(hard: tuple[float, ...], soft: tuple[float, ...], cov: tuple[float, ...], where: str) -> None:
    if math.sqrt(sum(v * v for v in hard)) > USABLE_MAX_T:
        raise CalibrationFileError(f"{where}: mag_hard_iron is over {USABLE_MAX_T} T (a field in µT or gauss?)")
    s = np.asarray(soft).reshape(3, 3)
    if np.linalg.det(s) <= 0.0 or np.linalg.cond(s) > MAX_CONDITION:
        raise CalibrationFileError(f"{where}: mag_soft_iron is singular, a reflection or ill-conditioned "
                                   f"(condition > {MAX_CONDITION:g})")
    c = np.asarray(cov).reshape(12, 12)
    scale = max(float(np.abs(c).max()), 1e-300)
    if not np.allclose(c, c.T, rtol=1e-6, atol=1e-9 * scale) or np.linalg.eigvalsh(0.5 * (c + c.T))[0] < -1e-9 * scale:
        raise CalibrationFileError(f"{where}: covariance is not symmetric positive semi-definite")


def load_calibration(path: str | os.PathLike[str]) -> MagCalibration:
    """Read a calibration file (module docstring); :class:`CalibrationFileError` when it cannot be used."""
    where = str(path)
    try:
        doc = yaml.safe_load(Path(path).read_text())
    except OSError as e:
        raise CalibrationFileError(f"{where}: cannot be read ({e.strerror or e})") from None
    except (UnicodeDecodeError, yaml.YAMLError) as e:
        raise CalibrationFileError(f"{where}: is not valid YAML ({str(e).splitlines()[0]})") from None
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
    _check(hard, soft, cov, where)
    return MagCalibration(hard_iron_t=hard, soft_iron=soft, covariance=cov, state=state,  # type: ignore[arg-type]
                          windows=windows, converged_after_s=None if conv is None else float(conv),
                          soft_iron_model=model)
