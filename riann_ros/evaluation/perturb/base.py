"""What every perturbation is: a kind with its parameters (:class:`Perturbation`, parsed from ``kind:args``) that
starts a :class:`Transform` per sequence, called with the sequence's pieces in order (ROS-free). The kinds:
:mod:`~riann_ros.evaluation.perturb.signal` (bias, magnetometer), :mod:`~riann_ros.evaluation.perturb.timing`
(jitter, rate, latency, FIFO), :mod:`~riann_ros.evaluation.perturb.dropout`; conditions and parsing:
:mod:`~riann_ros.evaluation.perturb.conditions`."""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import numpy as np
from numpy.typing import NDArray

from riann_ros.recording import Recording

NONE = "none"
DRAW_BLOCK = 1024  # random intervals drawn at a time (consumed in order: independent of chunking)


class Transform(ABC):
    """A perturbation applied to one sequence: called with its pieces in order, keeps state between them."""

    @abstractmethod
    def __call__(self, rec: Recording) -> Recording: ...

    def info(self) -> dict[str, Any]:
        """What happened to this sequence (for results.json)."""
        return {}


class Perturbation(ABC):
    """A kind of perturbation with its parameters (parsed from ``kind:args``)."""

    kind: str = ""

    @abstractmethod
    def text(self) -> str:
        """The canonical ``kind:args`` form."""

    def nominal_rate(self, rate_hz: float) -> float:
        """The stream's nominal rate after this perturbation, given the rate before."""
        return rate_hz

    @abstractmethod
    def start(self, rng: np.random.Generator) -> Transform:
        """A fresh transform for one sequence."""


def with_samples(rec: Recording, keep: NDArray[np.bool_] | None = None, **fields: Any) -> Recording:
    """A copy of ``rec`` restricted to ``keep`` and with some fields replaced."""
    sel = slice(None) if keep is None else keep
    base: dict[str, Any] = {
        "stamps_ns": rec.stamps_ns[sel],
        "acc": rec.acc[sel],
        "gyr": rec.gyr[sel],
        "quat_ref": None if rec.quat_ref is None else rec.quat_ref[sel],
        "score_mask": rec.score_mask[sel],
        "mag": None if rec.mag is None else rec.mag[sel],
    }
    base.update(fields)
    return Recording(**base, name=rec.name, dataset=rec.dataset, source=rec.source, frame_id=rec.frame_id,
                     meta=rec.meta)


def concat(*recs: Recording) -> Recording:
    has_ref = recs[0].quat_ref is not None
    return with_samples(
        recs[0],
        stamps_ns=np.concatenate([r.stamps_ns for r in recs]),
        acc=np.concatenate([r.acc for r in recs]),
        gyr=np.concatenate([r.gyr for r in recs]),
        quat_ref=np.concatenate([r.quat_ref for r in recs if r.quat_ref is not None]) if has_ref else None,
        score_mask=np.concatenate([r.score_mask for r in recs]),
        mag=np.concatenate([r.mag for r in recs if r.mag is not None]) if recs[0].mag is not None else None,
    )


def in_order(want: NDArray[np.int64], last: int | None, step_ns: int) -> NDArray[np.int64]:
    """Stamps ``want`` kept in order and at least ``step_ns`` apart, after ``last`` (the previous chunk's
    final stamp, None at the start): ``t'_k = max(want_k, t'_{k-1} + step)``."""
    k = np.arange(len(want), dtype=np.int64) * step_ns
    start = np.iinfo(np.int64).min // 2 if last is None else last + step_ns
    return np.maximum.accumulate(np.maximum(want - k, start)) + k
