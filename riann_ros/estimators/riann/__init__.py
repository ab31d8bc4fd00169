"""RIANN as a chain of stages; the folder lists them in order (see :mod:`.estimator` and docs/riann.md)."""

from riann_ros.estimators.riann.estimator import RiannEstimator
from riann_ros.estimators.riann.s4b_model import BatchedModel, default_model_path, open_model

__all__ = ["BatchedModel", "RiannEstimator", "default_model_path", "open_model"]
