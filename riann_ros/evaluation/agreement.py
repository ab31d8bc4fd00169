"""How far estimators agree with each other where there is no reference to score them against (ROS-free).

Per pair of estimators, per sample where both give an estimate, the inclination difference d = e_α(q_a, q_b)
(the paper's eq. 3 with one estimate in the reference's place: the angle between the two gravity directions,
heading ignored, symmetric). :class:`Agreement` keeps, chunk by chunk, its RMS, mean and max, the time of the max,
and its RMS per window of :data:`WINDOW_S`; the :data:`PARTS` windows with the largest RMS (no two neighbours) are
where the pair parts. Agreement is not accuracy: two estimators that share an error (the same wrong gyro bias, the
same accelerometer disturbance) agree and are both wrong; a large difference says that at least one is wrong
there, not which.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from riann_ros import quaternion as quat

#: s, the windows over which the difference is also summed: longer than the stamp jitter and a filter's
#: correction of one disturbance, shorter than a motion or a rest
WINDOW_S = 1.0
PARTS = 3  # windows reported per pair where the estimators part most


class Agreement:
    """Pairwise inclination differences of ``labels``' estimates, fed chunk by chunk (:meth:`add`); times in s
    from ``first_stamp``."""

    def __init__(self, labels: Sequence[str], first_stamp: int) -> None:
        self.labels = list(labels)
        self.pairs = list(itertools.combinations(range(len(labels)), 2))
        self.first = first_stamp
        k = len(self.pairs)
        self.n = np.zeros(k, dtype=np.int64)
        self.sum = np.zeros(k)
        self.sq = np.zeros(k)
        self.max = np.full(k, -math.inf)
        self.t_max = np.full(k, math.nan)
        self.win_n = np.zeros((k, 0), dtype=np.int64)
        self.win_sq = np.zeros((k, 0))
        self.n_estimated = np.zeros(len(labels), dtype=np.int64)  # samples each estimator gave an estimate for

    def add(self, stamps: NDArray[np.int64], qs: Sequence[NDArray[np.float64]]) -> None:
        """One chunk: its stamps and each estimator's estimates (N, 4), NaN rows where one gave none."""
        ok = [np.isfinite(q).all(axis=1) for q in qs]
        self.n_estimated += [int(o.sum()) for o in ok]
        if not self.pairs or not len(stamps):
            return
        t = (stamps - self.first) * 1e-9
        win = np.maximum(np.floor(t / WINDOW_S).astype(np.int64), 0)
        need = int(win.max()) + 1
        if need > self.win_n.shape[1]:
            grow = need - self.win_n.shape[1]
            self.win_n = np.pad(self.win_n, ((0, 0), (0, grow)))
            self.win_sq = np.pad(self.win_sq, ((0, 0), (0, grow)))
        for p, (a, b) in enumerate(self.pairs):
            both = ok[a] & ok[b]
            if not both.any():
                continue
            d = np.degrees(quat.inclination_error(qs[a][both], qs[b][both]))
            self.n[p] += len(d)
            self.sum[p] += float(d.sum())
            self.sq[p] += float(np.sum(d * d))
            k = int(np.argmax(d))
            if d[k] > self.max[p]:
                self.max[p], self.t_max[p] = float(d[k]), float(t[both][k])
            w = win[both]
            self.win_n[p] += np.bincount(w, minlength=need)[: self.win_n.shape[1]]
            self.win_sq[p] += np.bincount(w, weights=d * d, minlength=need)[: self.win_sq.shape[1]]

    def _parts(self, p: int) -> list[dict[str, float]]:
        """The windows of pair ``p`` with the largest RMS, no two neighbours, largest first."""
        n, sq = self.win_n[p], self.win_sq[p]
        rms = np.sqrt(np.divide(sq, n, out=np.zeros_like(sq), where=n > 0))
        chosen: list[int] = []
        for w in np.argsort(-rms, kind="stable"):
            if len(chosen) == PARTS or n[w] == 0:
                break
            if all(abs(int(w) - c) > 1 for c in chosen):
                chosen.append(int(w))
        return [{"start_s": w * WINDOW_S, "end_s": (w + 1) * WINDOW_S, "rms_deg": float(rms[w])} for w in chosen]

    def result(self) -> list[dict[str, Any]]:
        """Per pair: the labels ``a`` and ``b``, the samples compared, RMS, mean and max difference (°), the time
        of the max and the windows where they part most (``parts``: start, end, RMS)."""
        out = []
        for p, (a, b) in enumerate(self.pairs):
            n = int(self.n[p])
            out.append({"a": self.labels[a], "b": self.labels[b], "n": n,
                        "rms_deg": math.sqrt(self.sq[p] / n) if n else math.nan,
                        "mean_deg": float(self.sum[p] / n) if n else math.nan,
                        "max_deg": float(self.max[p]) if n else math.nan,
                        "t_max_s": float(self.t_max[p]), "parts": self._parts(p) if n else []})
        return out
