"""Estimator specs on the command line: ``riann``, ``madgwick:beta=0.1``, tuning grids (ROS-free).

Parameter names, types, defaults and ranges come from each estimator's ``PARAMS``
(:class:`~riann_ros.params.ParamSpec`); a spec's values are converted from text here and validated
once, by the estimator's constructor.

A spec may also carry the magnetometer input's calibration, as a node takes it (:data:`MAG_SPEC_PARAMS`):
``mag_hard_iron`` (T) and ``mag_soft_iron`` (row-major 3×3), a vector written with ``/`` between its numbers
(``vqf:mag_hard_iron=20e-6/0/-10e-6``: a ``,`` separates specs), and ``mag_calibration_file`` (a saved calibration,
``riann:mag_calibration_file=my_mag.yaml``; its path may hold neither ``:`` nor ``,``). They are not constructor
parameters: they make the stream's :class:`~riann_ros.magcal.input.MagConfig` and the online calibration's prior
(:meth:`EstimatorSpec.mag_config`, :attr:`EstimatorSpec.mag_prior`), as the node does at start: the file's hard and
soft iron replace the parameters, and with ``mag_calibration`` on its estimate with its covariance is where the
calibration starts. The file is read once, when the spec is parsed: one that is not a regular file or not a usable
calibration is a ``ValueError`` naming it.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from riann_ros.estimators import REGISTRY, estimator_class
from riann_ros.estimators.base import AttitudeEstimator
from riann_ros.magcal.input import MAG_PARAMS, MagConfig, UseMag
from riann_ros.magcal.records import MagCalibration, MagCalPrior
from riann_ros.magcal.store import CalibrationFileError, load_calibration
from riann_ros.params import ParamSpec, find

#: default tuning grids per estimator, keyed by parameter name as in PARAMS
DEFAULT_GRIDS: dict[str, dict[str, list[float]]] = {
    "madgwick": {"beta": [0.005, 0.01, 0.02, 0.033, 0.05, 0.075, 0.1, 0.15, 0.2, 0.3]},
    "mahony": {"kp": [0.1, 0.2, 0.5, 1.0, 2.0, 5.0], "ki": [0.0, 0.01, 0.03, 0.1, 0.3]},
    "vqf": {"tau_acc": [0.5, 1.0, 2.0, 3.0, 5.0, 8.0, 12.0]},
}

MAG_CALIBRATION_FILE = "mag_calibration_file"
#: the magnetometer input's parameters a spec may carry (module docstring); the node's names
MAG_SPEC_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec(MAG_CALIBRATION_FILE, "", "A saved magnetometer calibration (riann-mag-calibrate, the nodes' "
              "~/save_mag_calibration): its hard and soft iron replace mag_hard_iron and mag_soft_iron, and the online "
              "calibration starts from it."),
    find(MAG_PARAMS, "mag_hard_iron"),
    find(MAG_PARAMS, "mag_soft_iron"),
)
_MAG_SPECS = {p.name: p for p in MAG_SPEC_PARAMS}


@dataclass(frozen=True)
class EstimatorSpec:
    """An estimator name with parameters and a readable label, e.g. ``madgwick(beta=0.1)``; ``mag``: the
    magnetometer input's parameters given (:data:`MAG_SPEC_PARAMS`), ``calibration``: the file's, read at parse."""

    name: str
    params: tuple[tuple[str, Any], ...] = ()
    label: str = ""
    mag: tuple[tuple[str, Any], ...] = ()
    calibration: MagCalibration | None = None

    @property
    def kwargs(self) -> dict[str, Any]:
        """The estimator's constructor parameters."""
        return dict(self.params)

    @property
    def node_params(self) -> dict[str, Any]:
        """The parameters of a node running this spec: the constructor's and the magnetometer input's (the file's
        path made absolute: the node reads it itself)."""
        mag = dict(self.mag)
        if MAG_CALIBRATION_FILE in mag:
            mag[MAG_CALIBRATION_FILE] = str(Path(mag[MAG_CALIBRATION_FILE]).resolve())
        return {**self.kwargs, **mag}

    def create(self) -> AttitudeEstimator:
        return estimator_class(self.name)(**self.kwargs)

    def mag_config(self, use_mag: str | UseMag = UseMag.AUTO) -> MagConfig:
        """The stream's magnetometer parameters: ``use_mag`` (the evaluator's ``--use-mag``), the spec's hard and
        soft iron, replaced by the file's when it has one (as the node at start)."""
        mag = {k: v for k, v in self.mag if k != MAG_CALIBRATION_FILE}
        if self.calibration is not None:
            mag.update(mag_hard_iron=self.calibration.hard_iron_t, mag_soft_iron=self.calibration.soft_iron)
        return MagConfig(use_mag=UseMag.parse(use_mag), **mag)

    @property
    def mag_prior(self) -> MagCalPrior | None:
        """Where the online calibration starts: the file's estimate with its covariance (None: the parameters)."""
        return None if self.calibration is None else MagCalPrior.from_calibration(self.calibration)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"label": self.label, "name": self.name, "params": self.kwargs}
        if self.mag:
            out["mag_params"] = {k: list(v) if isinstance(v, tuple) else v for k, v in self.mag}
        if self.calibration is not None:
            c = self.calibration
            out["mag_calibration_loaded"] = {"mag_hard_iron": list(c.hard_iron_t), "mag_soft_iron": list(c.soft_iron),
                                             "hard_iron_sd": list(c.hard_iron_sd_t), "state": c.state,
                                             "windows": c.windows, "soft_iron_model": c.soft_iron_model}
        return out

    @classmethod
    def of(cls, name: str, params: dict[str, Any] | None = None, label: str | None = None,
           mag: dict[str, Any] | None = None, calibration: MagCalibration | None = None) -> EstimatorSpec:
        params, mag = params or {}, mag or {}
        return cls(name, tuple(params.items()),
                   label if label is not None else make_label(name, {**params, **mag}), tuple(mag.items()),
                   calibration)


def _value_text(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:g}"
    if isinstance(v, tuple):
        return "/".join(_value_text(x) for x in v)
    return str(v)


def make_label(name: str, params: dict[str, Any]) -> str:
    """``madgwick(beta=0.1)``, ``vqf(mag_hard_iron=2e-05/0/-1e-05)``; the bare name without parameters."""
    if not params:
        return name
    return f"{name}({', '.join(f'{k}={_value_text(v)}' for k, v in params.items())})"


def _known(name: str) -> tuple[type[AttitudeEstimator], dict[str, ParamSpec]]:
    if name not in REGISTRY:
        raise ValueError(f"unknown estimator {name!r}; known: {', '.join(REGISTRY)}")
    cls = estimator_class(name)  # ImportError if the module is missing
    return cls, {p.name.lower(): p for p in cls.PARAMS}


def _param(text: str, name: str, specs: dict[str, ParamSpec], key: str) -> ParamSpec:
    spec = specs.get(key.strip().lower())
    if spec is None:
        known = ", ".join(p.name for p in specs.values()) or "none"
        raise ValueError(f"{text!r}: unknown parameter {key.strip()!r} for {name}; known: {known}")
    return spec


def parse_estimator(text: str) -> EstimatorSpec:
    """``"madgwick:beta=0.033"`` / ``"mahony:kp=1:ki=0.3"`` / ``"riann"`` → :class:`EstimatorSpec`.

    The name and the parameters are checked against the estimator's ``PARAMS`` (``ValueError``
    otherwise, naming the known estimators or parameters).
    """
    parts = [p.strip() for p in text.strip().split(":")]
    name = parts[0].lower()
    if not name:
        raise ValueError(f"empty estimator name in {text!r}")
    cls, specs = _known(name)
    params: dict[str, Any] = {}
    mag: dict[str, Any] = {}
    for item in parts[1:]:
        if "=" not in item:
            raise ValueError(f"{text!r}: expected name=value after ':', got {item!r}")
        key, value = item.split("=", 1)
        if key.strip().lower() in _MAG_SPECS:
            mag.update(_mag_param(text, cls, key.strip().lower(), value.strip()))
            continue
        spec = _param(text, name, {**specs, **_MAG_SPECS}, key)
        params[spec.name] = spec.parse(value.strip())
    cls(**params)  # the combination (and fails early, not in a worker)
    calibration = _calibration(text, mag[MAG_CALIBRATION_FILE]) if MAG_CALIBRATION_FILE in mag else None
    return EstimatorSpec.of(name, params, mag=mag, calibration=calibration)


def _mag_param(text: str, cls: type[AttitudeEstimator], key: str, value: str) -> dict[str, Any]:
    """One of :data:`MAG_SPEC_PARAMS`, its value parsed (a vector's numbers between ``/``)."""
    if not cls.USES_MAG:
        raise ValueError(f"{text!r}: {key} is a magnetometer parameter; {cls.__name__} does not use the field")
    spec = _MAG_SPECS[key]
    if key == MAG_CALIBRATION_FILE:
        if not value:
            raise ValueError(f"{text!r}: {key} needs a file (the path may hold neither ':' nor ',')")
        return {key: value}
    n = len(spec.default)  # type: ignore[arg-type]
    try:
        numbers = [float(v) for v in value.split("/")]
    except ValueError:
        numbers = []
    if len(numbers) != n:
        raise ValueError(f"{text!r}: {key} must be {n} numbers between '/' (e.g. {key}={'/'.join(['0'] * n)}), "
                         f"got {value!r}")
    try:
        return {key: spec.validate(numbers)}
    except ValueError as exc:
        raise ValueError(f"{text!r}: {exc}") from None


def _calibration(text: str, path: str) -> MagCalibration:
    """The calibration saved in ``path`` (ValueError naming the file when it is none: not a regular file, not a
    calibration, unusable numbers)."""
    p = Path(path)
    if not p.is_file():
        what = "does not exist" if not p.exists() else "is not a regular file"
        raise ValueError(f"{text!r}: mag_calibration_file {path} {what}")
    try:
        return load_calibration(p)
    except CalibrationFileError as exc:
        raise ValueError(f"{text!r}: mag_calibration_file refused: {exc}") from None


def parse_estimators(text: str | Sequence[str]) -> list[EstimatorSpec]:
    """Comma-separated specs (or a list of them) → unique-labelled specs."""
    items = text.split(",") if isinstance(text, str) else [s for t in text for s in t.split(",")]
    out: list[EstimatorSpec] = []
    for item in items:
        if _is_number(item):
            raise ValueError(f"{item.strip()!r} is no estimator spec: in a spec a vector's numbers are written between "
                             "'/' (vqf:mag_hard_iron=20e-6/0/-10e-6), since ',' separates specs")
        if item.strip():
            spec = parse_estimator(item)
            if spec.label in {s.label for s in out}:
                raise ValueError(f"estimator {spec.label} given twice")
            out.append(spec)
    if not out:
        raise ValueError("no estimators given")
    return out


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def available_estimators() -> list[str]:
    """Registered estimators whose module imports (others lack a dependency)."""
    names = []
    for name in REGISTRY:
        try:
            estimator_class(name)
        except Exception:
            continue
        names.append(name)
    return names


def parse_grid(text: str) -> tuple[str, dict[str, list[Any]]]:
    """``"madgwick"`` (default grid) or ``"mahony:kp=0.5/1/2:ki=0/0.3"`` → (name, {param: values})."""
    parts = [p.strip() for p in text.split(":") if p.strip()]
    name = parts[0].lower() if parts else ""
    if name not in REGISTRY:
        raise ValueError(f"unknown estimator {name!r} to tune; known: {', '.join(REGISTRY)}")
    _, specs = _known(name)
    grid: dict[str, list[Any]] = {}
    if len(parts) == 1:
        grid = {specs[k].name: list(v) for k, v in DEFAULT_GRIDS.get(name, {}).items() if k in specs}
        if not grid:
            raise ValueError(f"no default tuning grid for {name}; give one, e.g. {name}:param=1/2/3")
    for item in parts[1:]:
        if "=" not in item:
            raise ValueError(f"{text!r}: expected param=v1/v2/..., got {item!r}")
        key, values = item.split("=", 1)
        spec = _param(text, name, specs, key)
        grid[spec.name] = [spec.parse(v) for v in values.split("/") if v.strip()]
    return name, grid


def grid_specs(name: str, grid: dict[str, list[Any]]) -> list[EstimatorSpec]:
    """One spec per combination of the grid's values."""
    keys = list(grid)
    return [EstimatorSpec.of(name, dict(zip(keys, combo, strict=True))) for combo in itertools.product(*grid.values())]
