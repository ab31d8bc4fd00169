"""The node's saved magnetometer calibration: the ``mag_calibration_file`` parameter (read at start), the
``~/save_mag_calibration`` and ``~/save_mag_calibration_force`` services (write it), the physical check of the
``mag_hard_iron`` / ``mag_soft_iron`` parameters and the calibration's lines in ``/diagnostics``.

* **The parameters** ``mag_hard_iron`` and ``mag_soft_iron`` are checked by physics
  (:mod:`riann_ros.magcal.validate`): a value refused at start is logged once (one WARN naming the parameter and
  the reason) and replaced by its default (no hard iron, identity soft iron: no value was good before it); a value
  refused at run time is not applied (the set fails with the reason, one WARN), the last good one stays.
* **At start** a temporary file left beside the file by a save that was cut off is removed, and the file
  (:mod:`riann_ros.magcal.store`, written by ``riann-mag-calibrate`` or by the service) is read once: its
  ``mag_hard_iron`` and ``mag_soft_iron`` replace the parameters of those names, and with the online calibration on
  (``mag_calibration``) the estimate with its covariance is where the calibration starts
  (:meth:`~riann_ros.magcal.records.MagCalPrior.from_calibration`): a robot converges once in its life, not at every
  boot. A file that does not exist yet is no error (the service writes it). A file that cannot be used (not a
  regular file, too large, not a calibration file, a calibration validation refuses) is refused with one log
  message naming the file and the problem, and a WARN in ``/diagnostics``; the node runs on its parameters.
* **The service** writes the online calibration's current estimate to ``mag_calibration_file``, atomically (a crash
  leaves the old file or the new one), keeping the file's mode. It writes that path only, replaces a file there only
  when it is a calibration file, and refuses (the response says why) without the parameter, with the calibration
  off, before the calibration holds a single window of rotation (nothing learned: a good file is not replaced by
  nothing), or with an estimate validation refuses. It never downgrades: it keeps a file whose calibration the
  estimate would make less certain (:func:`~riann_ros.magcal.store.less_certain`: a lower state, or the same state
  with a less certain hard iron), or to which it adds no window since it was loaded at start (``success: false``,
  "kept the file: ..."). **The force service** writes it all the same (std_srvs/Trigger carries no argument, so the
  choice is the service called, made anew at each call).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from riann_ros.magcal.input import MAG_PARAMS
from riann_ros.magcal.records import UT, MagCalibration, MagCalPrior, MagCalStatus
from riann_ros.magcal.store import (
    CalibrationFileError,
    less_certain,
    load_calibration,
    remove_temporaries,
    save_calibration,
)
from riann_ros.magcal.validate import calibration_refusals, hard_iron_refusals, soft_iron_refusals
from riann_ros.params import ParamSpec, defaults

MAG_CALIBRATION_FILE = ParamSpec(
    "mag_calibration_file", "", "Saved magnetometer calibration (YAML of riann-mag-calibrate or of the "
    "~/save_mag_calibration service), read at start: its mag_hard_iron and mag_soft_iron replace those parameters and "
    "the online calibration (mag_calibration) continues from it; the file the service writes. Empty: none.")
SAVE_SERVICE = "~/save_mag_calibration"
SAVE_FORCE_SERVICE = "~/save_mag_calibration_force"
_CHECKS = {"mag_hard_iron": hard_iron_refusals, "mag_soft_iron": soft_iron_refusals}
_DEFAULTS = {k: v for k, v in defaults(MAG_PARAMS).items() if k in _CHECKS}


def parameter_refusals(values: Mapping[str, Any]) -> dict[str, list[str]]:
    """``{name: reasons}`` for each of ``mag_hard_iron`` / ``mag_soft_iron`` in ``values`` that validation
    refuses."""
    return {name: reasons for name, check in _CHECKS.items() if name in values and (reasons := check(values[name]))}


def check_changes(changes: dict[str, Any]) -> dict[str, Any]:
    """Run-time parameter changes, or ``ValueError`` naming each of ``mag_hard_iron`` / ``mag_soft_iron`` that
    validation refuses (none is applied then)."""
    refused = parameter_refusals(changes)
    if refused:
        raise ValueError("; ".join(f"{k} refused: {'; '.join(v)}" for k, v in refused.items())
                         + " (the value in use stays)")
    return changes


def start_file(values: dict[str, Any]) -> tuple[CalibrationFile, list[tuple[str, str]]]:
    """At start: ``mag_hard_iron`` / ``mag_soft_iron`` of the start-up ``values`` checked (a refused one is replaced
    by its default), then ``mag_calibration_file`` read (a usable file's hard and soft iron replace them); the file
    and the parameters' warnings ((level, text)) to log."""
    refused = []
    for name, reasons in parameter_refusals(values).items():
        refused.append(("warning", f"parameter {name} = {list(values[name])} refused: {'; '.join(reasons)}; the "
                        f"node runs on its default {list(_DEFAULTS[name])}"))
        values[name] = _DEFAULTS[name]
    f = CalibrationFile(values["mag_calibration_file"])
    if f.loaded is not None:
        values["mag_hard_iron"], values["mag_soft_iron"] = f.loaded.hard_iron_t, f.loaded.soft_iron
    return f, refused


def _vector_ut(v: tuple[float, ...]) -> str:
    return ", ".join(f"{x / UT:+.2f}" for x in v)


def describe(cal: MagCalibration) -> str:
    """One line: state, hard iron ± σ (µT), windows."""
    sd = ", ".join(f"{v / UT:.2f}" for v in cal.hard_iron_sd_t)
    return f"{cal.state}, hard iron ({_vector_ut(cal.hard_iron_t)}) ± ({sd}) µT, {cal.windows} windows"


class CalibrationFile:
    """``mag_calibration_file`` of one node: what was read at start (:attr:`loaded`, None: nothing usable) and the
    start-up messages ((level, text); level ``info`` or ``warning``) for the node to log."""

    def __init__(self, path: str) -> None:
        self.path = path.strip()
        self.loaded: MagCalibration | None = None
        self.problem: str | None = None  # why the file at start was refused
        self.log: list[tuple[str, str]] = []
        if not self.path:
            return
        for tmp in remove_temporaries(self.path):
            self.log.append(("info", f"removed {tmp}: a temporary file left by a save of {self.path} that was cut "
                             "off"))
        if not Path(self.path).exists():
            self.log.append(("info", f"mag_calibration_file {self.path} does not exist yet: the calibration starts "
                             f"from mag_hard_iron and mag_soft_iron; {SAVE_SERVICE} writes it"))
            return
        try:
            self.loaded = load_calibration(self.path)
        except CalibrationFileError as exc:
            self.problem = str(exc)
            self.log.append(("warning", f"mag_calibration_file refused: {exc}; running on the parameters "
                             "mag_hard_iron and mag_soft_iron"))
            return
        self.log.append(("info", f"mag_calibration_file {self.path} loaded: {describe(self.loaded)}"))

    @property
    def prior(self) -> MagCalPrior | None:
        """Where the online calibration starts: the loaded calibration (None: the parameters)."""
        return MagCalPrior.from_calibration(self.loaded) if self.loaded is not None else None

    def save(self, cal: MagCalibration | None, force: bool = False) -> tuple[bool, str]:
        """Write ``cal`` (the estimator's current estimate; None: its calibration is off) → (success, message);
        unless ``force``, not over a file it would downgrade (module docstring)."""
        if not self.path:
            return False, ("no mag_calibration_file: start the node with -p mag_calibration_file:=<path> to name "
                           "the file to write; nothing written")
        if cal is None:
            return False, "the online magnetometer calibration is off (mag_calibration: false); nothing written"
        if cal.windows == 0:
            return False, (f"nothing learned yet ({cal.state}: no window of rotation so far; turn the sensor); "
                           f"{self.path} not written")
        reasons = calibration_refusals(cal)
        if reasons:
            return False, f"the current calibration is refused ({'; '.join(reasons)}); {self.path} not written"
        why = None if force else self._downgrade(cal)
        if why is not None:
            return False, f"kept the file: {why}; {self.path} not written ({SAVE_FORCE_SERVICE} replaces it)"
        try:
            written = save_calibration(self.path, cal)
        except (CalibrationFileError, OSError) as exc:
            return False, f"{exc}; nothing written"
        return True, f"wrote {written}: {describe(cal)}"

    def _downgrade(self, cal: MagCalibration) -> str | None:
        """Why writing ``cal`` would downgrade the file there now (None: it would not, or there is no usable
        calibration there; a file of another kind is refused by the write itself)."""
        try:
            old = load_calibration(self.path)
        except CalibrationFileError:
            return None
        if old == self.loaded and cal.windows <= old.windows:
            return (f"the current calibration adds no window of rotation to the {old.windows} of the file loaded at "
                    "start")
        return less_certain(cal, old)


def status_values(status: MagCalStatus | None, file: CalibrationFile) -> dict[str, str]:
    """The calibration's ``/diagnostics`` values (none when the estimator does not calibrate online)."""
    out: dict[str, str] = {}
    if status is not None:
        conv = status.converged_after_s
        out.update({
            "mag calibration": status.state,
            "mag calibration in use": ("the configured or saved one (the gyro-aided test finds it the more probable)"
                                       if status.prior_holds else "the online estimate"),
            "mag hard iron (uT)": _vector_ut(status.hard_iron_t),
            "mag hard iron sd (uT)": ", ".join(f"{s / UT:.2f}" for s in status.hard_iron_sd_t),
            "mag calibration heading bound (deg)": f"{math.degrees(status.heading_sd_bound_rad):.2f}",
            "mag calibration windows (used / rejected)": f"{status.windows} / {status.rejected}",
            "mag calibration unit weight": f"{status.unit_weight:.2f}",
            "mag calibration converged after (s)": "not yet" if conv is None else f"{conv:.1f}",
        })
    if file.path:
        out["mag calibration file"] = (f"{file.path} (refused at start: see the log)" if file.problem else
                                       f"{file.path} ({'loaded at start' if file.loaded else 'not read at start'})")
    return out
