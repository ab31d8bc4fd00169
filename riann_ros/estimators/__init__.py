"""Attitude estimators behind one interface (see :mod:`riann_ros.estimators.base`).

``create("riann")``, ``create("madgwick", beta=0.1)``, … — modules are imported lazily so that a
missing optional dependency of one estimator does not break the others.
"""

from __future__ import annotations

import importlib
from typing import Any

from riann_ros.estimators.base import AttitudeEstimator, ParamSpec

# name -> "module:Class"
REGISTRY: dict[str, str] = {
    "riann": "riann_ros.estimators.riann:RiannEstimator",
    "madgwick": "riann_ros.estimators.madgwick:MadgwickEstimator",
    "mahony": "riann_ros.estimators.mahony:MahonyEstimator",
    "vqf": "riann_ros.estimators.vqf_estimator:VqfEstimator",
    "consensus": "riann_ros.estimators.consensus:ConsensusEstimator",
}


def estimator_class(name: str) -> type[AttitudeEstimator]:
    """The estimator class registered under ``name``; ``ValueError`` names the known ones."""
    try:
        target = REGISTRY[name]
    except KeyError:
        raise ValueError(f"unknown estimator {name!r}; known: {', '.join(REGISTRY)}") from None
    module, cls = target.split(":")
    return getattr(importlib.import_module(module), cls)


def create(name: str, **params: Any) -> AttitudeEstimator:
    """Instantiate the estimator ``name`` with validated parameters."""
    return estimator_class(name)(**params)


__all__ = ["REGISTRY", "AttitudeEstimator", "ParamSpec", "create", "estimator_class"]
