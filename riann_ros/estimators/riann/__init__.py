"""RIANN as a chain of stages; the folder lists them in order (see :mod:`.estimator` and docs/riann.md)."""

from riann_ros.estimators.riann.estimator import RiannEstimator
from riann_ros.estimators.riann.s4_network import HIDDEN_SHAPE, default_model_path, make_session

__all__ = ["HIDDEN_SHAPE", "RiannEstimator", "default_model_path", "make_session"]
