"""Lost messages (``dropout:``, ROS-free): holes of a drawn length, about every T s, starting where the sensor
moves. Definitions: :data:`~riann_ros.evaluation.perturb.conditions.DEFINITIONS`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from riann_ros.constants import NS_PER_S
from riann_ros.evaluation.perturb.base import Perturbation, Transform, with_samples
from riann_ros.recording import Recording


# ---------------------------------------------------------------------------------------------------
# dropouts
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Dropout(Perturbation):
    """Holes of ``lo``–``hi`` s about every ``every`` s (exponential spacing), starting at a scored sample."""

    lo: float = 0.1
    hi: float = 0.6
    every: float = 10.0
    kind = "dropout"

    def text(self) -> str:
        return f"dropout:{self.lo:g}-{self.hi:g}s@{self.every:g}s"

    def start(self, rng: np.random.Generator) -> Transform:
        return _Holes(self, rng)


class _Holes(Transform):
    def __init__(self, p: Dropout, rng: np.random.Generator) -> None:
        self.p = p
        self.rng = rng
        self.candidate: int | None = None  # earliest start of the next hole (ns)
        self.hole: tuple[int, int] | None = None  # current hole [start, end)
        self.holes = 0
        self.removed = 0

    def _next_candidate(self, after: int) -> None:
        self.candidate = after + round(self.rng.exponential(self.p.every) * NS_PER_S)

    def __call__(self, rec: Recording) -> Recording:
        st = rec.stamps_ns
        if self.candidate is None:
            self._next_candidate(int(st[0]))
        keep = np.ones(len(st), dtype=bool)
        while True:
            if self.hole is not None:
                a, b = self.hole
                keep &= ~((st >= a) & (st < b))
                if b > st[-1]:
                    break  # the hole goes on into the next piece
                self.hole = None
                self._next_candidate(b)
            at = np.flatnonzero((st >= self.candidate) & rec.score_mask)  # type: ignore[operator]
            if not len(at):
                break  # no scored sample after the candidate in this piece: wait for the next
            start = int(st[at[0]])
            self.hole = (start, start + round(self.rng.uniform(self.p.lo, self.p.hi) * NS_PER_S))
            self.holes += 1
        self.removed += int((~keep).sum())
        return rec if keep.all() else with_samples(rec, keep)

    def info(self) -> dict[str, Any]:
        return {"holes": self.holes, "samples_removed": self.removed}
