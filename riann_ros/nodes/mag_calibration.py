"""The node's saved magnetometer calibration: the ``mag_calibration_file`` parameter (read at start), the
``~/save_mag_calibration`` service (writes it) and the calibration's lines in ``/diagnostics``.

* **At start** the file (:mod:`riann_ros.magcal.store`, written by ``riann-mag-calibrate`` or by the service) is
  read once: its ``mag_hard_iron`` and ``mag_soft_iron`` replace the parameters of those names, and with the online
  calibration on (``mag_calibration``) the estimate with its covariance is where the calibration starts
  (:meth:`~riann_ros.magcal.records.MagCalPrior.from_calibration`): a robot converges once in its life, not at every
  boot. A file that does not exist yet is no error (the service writes it). A file that cannot be used is refused
  with one log message naming the file and the problem, and a WARN in ``/diagnostics``; the node runs on its
  parameters.
* **The service** writes the online calibration's current estimate to ``mag_calibration_file``, atomically (a crash
  leaves the old file or the new one). It writes that path only, replaces a file there only when it is a calibration
  file, and refuses (the response says why) without the parameter, with the calibration off, or before the
  calibration holds a single window of rotation (nothing learned: a good file is not replaced by nothing).
"""

from __future__ import annotations

import math
from pathlib import Path

from riann_ros.magcal.records import UT, MagCalibration, MagCalPrior, MagCalStatus
from riann_ros.magcal.store import CalibrationFileError, load_calibration, save_calibration
from riann_ros.params import ParamSpec

MAG_CALIBRATION_FILE = ParamSpec(
    "mag_calibration_file", "", "Saved magnetometer calibration (YAML of riann-mag-calibrate or of the "
    "~/save_mag_calibration service), read at start: its mag_hard_iron and mag_soft_iron replace those parameters and "
    "the online calibration (mag_calibration) continues from it; the file the service writes. Empty: none.")
SAVE_SERVICE = "~/save_mag_calibration"


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

    def save(self, cal: MagCalibration | None) -> tuple[bool, str]:
        """Write ``cal`` (the estimator's current estimate; None: its calibration is off) → (success, message)."""
        if not self.path:
            return False, ("no mag_calibration_file: start the node with -p mag_calibration_file:=<path> to name "
                           "the file to write; nothing written")
        if cal is None:
            return False, "the online magnetometer calibration is off (mag_calibration: false); nothing written"
        if cal.windows == 0:
            return False, (f"nothing learned yet ({cal.state}: no window of rotation so far; turn the sensor); "
                           f"{self.path} not written")
        try:
            written = save_calibration(self.path, cal)
        except (CalibrationFileError, OSError) as exc:
            return False, f"{exc}; nothing written"
        return True, f"wrote {written}: {describe(cal)}"


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
