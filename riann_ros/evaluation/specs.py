"""Estimator specs on the command line: ``riann``, ``madgwick:beta=0.1``, tuning grids (ROS-free).

Parameter names, types, defaults and ranges come from each estimator's ``PARAMS``
(:class:`~riann_ros.params.ParamSpec`); a spec's values are converted from text here and validated
once, by the estimator's constructor.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from riann_ros.estimators import REGISTRY, estimator_class
from riann_ros.estimators.base import AttitudeEstimator
from riann_ros.params import ParamSpec

#: default tuning grids per estimator, keyed by parameter name as in PARAMS
DEFAULT_GRIDS: dict[str, dict[str, list[float]]] = {
    "madgwick": {"beta": [0.005, 0.01, 0.02, 0.033, 0.05, 0.075, 0.1, 0.15, 0.2, 0.3]},
    "mahony": {"kp": [0.1, 0.2, 0.5, 1.0, 2.0, 5.0], "ki": [0.0, 0.01, 0.03, 0.1, 0.3]},
    "vqf": {"tau_acc": [0.5, 1.0, 2.0, 3.0, 5.0, 8.0, 12.0]},
}


@dataclass(frozen=True)
class EstimatorSpec:
    """An estimator name with parameters and a readable label, e.g. ``madgwick(beta=0.1)``."""

    name: str
    params: tuple[tuple[str, Any], ...] = ()
    label: str = ""

    @property
    def kwargs(self) -> dict[str, Any]:
        return dict(self.params)

    def create(self) -> AttitudeEstimator:
        return estimator_class(self.name)(**self.kwargs)

    def to_dict(self) -> dict[str, Any]:
        return {"label": self.label, "name": self.name, "params": self.kwargs}

    @classmethod
    def of(cls, name: str, params: dict[str, Any] | None = None, label: str | None = None) -> EstimatorSpec:
        params = params or {}
        return cls(name, tuple(params.items()), label if label is not None else make_label(name, params))


def make_label(name: str, params: dict[str, Any]) -> str:
    """``madgwick(beta=0.1)``; the bare name without parameters."""
    if not params:
        return name
    inner = ", ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in params.items())
    return f"{name}({inner})"


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
    for item in parts[1:]:
        if "=" not in item:
            raise ValueError(f"{text!r}: expected name=value after ':', got {item!r}")
        key, value = item.split("=", 1)
        spec = _param(text, name, specs, key)
        params[spec.name] = spec.parse(value.strip())
    cls(**params)  # the combination (and fails early, not in a worker)
    return EstimatorSpec.of(name, params)


def parse_estimators(text: str | Sequence[str]) -> list[EstimatorSpec]:
    """Comma-separated specs (or a list of them) → unique-labelled specs."""
    items = text.split(",") if isinstance(text, str) else [s for t in text for s in t.split(",")]
    out: list[EstimatorSpec] = []
    for item in items:
        if item.strip():
            spec = parse_estimator(item)
            if spec.label in {s.label for s in out}:
                raise ValueError(f"estimator {spec.label} given twice")
            out.append(spec)
    if not out:
        raise ValueError("no estimators given")
    return out


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
