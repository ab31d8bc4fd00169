"""The first pass over a source (ROS-free): :func:`summarise` checks the input (samples; where it has a reference,
scored samples with one: an input without a reference orientation is evaluated without scores), finds the motion
onset (first scored sample) and the rates (1 / median stamp step) of the whole sequence and of
the sequence from the motion onset; then, over the samples before the motion onset only, the rest whose mean gyro
is the turn-on bias (:mod:`~riann_ros.evaluation.rest`: detected from the signals, or given by hand)."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from riann_ros.evaluation.errors import EvalError
from riann_ros.evaluation.rest import GIVEN, Rest, RestDetector
from riann_ros.evaluation.sources import Source, read_whole
from riann_ros.recording import Recording


def median_rate(hist: dict[int, int]) -> float:
    """``Recording.rate_hz`` (1 / median step) from a histogram of the stamp steps (ns → count)."""
    n = sum(hist.values())
    if n == 0:
        return float("nan")
    keys = sorted(hist)
    cum = np.cumsum([hist[k] for k in keys])

    def kth(k: int) -> int:  # the k-th smallest step (0-based)
        return keys[int(np.searchsorted(cum, k, side="right"))]

    if n % 2:
        med = float(np.int64(kth(n // 2)) * 1e-9)
    else:
        med = float(np.median(np.array([kth(n // 2 - 1), kth(n // 2)], dtype=np.int64) * 1e-9))
    return 1.0 / med


def _add_steps(hist: dict[int, int], steps: NDArray[np.int64]) -> None:
    if len(steps):
        vals, counts = np.unique(steps, return_counts=True)
        for v, c in zip(vals.tolist(), counts.tolist(), strict=True):
            hist[v] = hist.get(v, 0) + c


@dataclass
class Summary:
    """What the first pass over a source gives before the estimators run (all of bounded size)."""

    name: str
    dataset: str
    citation: str
    frame_id: str
    n: int
    first_stamp: int
    i0: int  # first scored sample (the motion onset); the rest is looked for in [0, i0)
    stamp_i0: int
    rate_all: float  # 1 / median stamp step of the whole sequence
    rate_from_i0: float  # … of the sequence from i0 on
    rest: Rest = field(default_factory=Rest)  # the rest whose mean gyro is the turn-on bias (maybe none)
    has_reference: bool = True  # False: no reference orientation at any sample (nothing to score against)


class _Pass:
    """Running state of :func:`summarise`."""

    def __init__(self) -> None:
        self.n = self.first_stamp = self.stamp_i0 = 0
        self.last: int | None = None
        self.i0 = -1
        self.has_ref = self.ref_any = self.scored_any = self.scored_ref = False
        self.hist_all: dict[int, int] = {}
        self.hist_i0: dict[int, int] = {}
        self.meta: tuple[str, str, str, str] = ("", "", "", "")

    def add(self, c: Recording) -> None:
        m = len(c)
        if self.n == 0:
            self.first_stamp = int(c.stamps_ns[0])
            self.meta = (c.name, c.dataset, c.source, c.frame_id)
            self.has_ref = c.quat_ref is not None
        idx = np.arange(self.n, self.n + m)  # global index of each sample
        if self.last is not None:
            steps, later = np.diff(c.stamps_ns, prepend=np.int64(self.last)), idx
        else:
            steps, later = np.diff(c.stamps_ns), idx[1:]  # later: global index of each step's later sample
        _add_steps(self.hist_all, steps)
        if self.i0 < 0 and c.score_mask.any():
            k = int(np.argmax(c.score_mask))
            self.i0, self.stamp_i0 = self.n + k, int(c.stamps_ns[k])
        if self.i0 >= 0:
            _add_steps(self.hist_i0, steps[later > self.i0])
        self.scored_any |= bool(c.score_mask.any())
        if self.has_ref and c.quat_ref is not None:
            ok = np.isfinite(c.quat_ref).all(axis=1)
            self.ref_any |= bool(ok.any())
            self.scored_ref |= bool((ok & c.score_mask).any())
        self.last = int(c.stamps_ns[-1])
        self.n += m

    def summary(self, p: Path, reference_required: bool = False) -> Summary:
        """The summary; EvalError for an input that cannot be evaluated. Without a reference orientation at any
        sample the input is reference-free (``has_reference`` False), unless ``reference_required`` (a reference
        topic was named)."""
        if self.n < 2:
            raise EvalError(f"{p}: fewer than 2 IMU samples")
        has_reference = self.has_ref and self.ref_any
        if not has_reference and reference_required:
            raise EvalError(f"{p}: no reference orientation on the --ground-truth-topic (nothing to score against)")
        if has_reference and not self.scored_any:
            raise EvalError(f"{p}: no scored samples (score mask is empty)")
        if has_reference and not self.scored_ref:
            raise EvalError(f"{p}: no scored samples with a reference")
        name, dataset, citation, frame_id = self.meta
        if not name or name == "sequence":
            name = p.stem if p.is_file() else p.name
        return Summary(
            name=name,
            dataset=dataset or "unknown",
            citation=citation,
            frame_id=frame_id,
            n=self.n,
            first_stamp=self.first_stamp,
            i0=max(self.i0, 0),
            stamp_i0=self.stamp_i0,
            rate_all=median_rate(self.hist_all),
            rate_from_i0=median_rate(self.hist_i0),
            has_reference=has_reference,
        )


def summarise(src: Source, rest: tuple[float, float] | Rest | None = None) -> Summary:
    """The first pass over ``src``: checks (raising :class:`EvalError` naming the input), motion onset and rates;
    then the rest before the motion onset (a second pass over those samples only). ``rest``: None: detect it; the
    rest given by hand, (start, end) in seconds from the first sample; or the :class:`Rest` of this recording at
    another rate (the resampled recording's rest is the same stretch of time: no rest there, none here)."""
    state = _Pass()
    for c in src.chunks():
        state.add(c)
    summary = state.summary(src.path, src.topics.reference is not None)
    summary.rest = find_rest(src, summary, rest) if summary.has_reference else Rest()
    return summary


def find_rest(src: Source, summary: Summary, given: tuple[float, float] | Rest | None = None) -> Rest:
    """The rest of ``src`` (see :mod:`~riann_ros.evaluation.rest` and :func:`summarise`), reading only as far as
    needed."""
    if isinstance(given, Rest):
        if not given.found or given.start_s is None or given.end_s is None:
            return Rest()
        found = find_rest(src, summary, (given.start_s, given.end_s + 1e-6))  # the span, its last sample included
        found.source = given.source
        return found
    if summary.i0 <= 0 and given is None:
        return Rest()
    det = RestDetector(summary.rate_all, summary.i0, summary.first_stamp, given)
    chunks = src.chunks()
    try:
        for c in chunks:
            det.add(c)
            if det.done:
                break
    finally:
        close = getattr(chunks, "close", None)
        if close is not None:
            close()
    found = det.result()
    if given is not None and found.source != GIVEN:
        length = (det.last_stamp - summary.first_stamp) * 1e-9
        raise EvalError(f"{src.path}: --rest {given[0]:g}:{given[1]:g} holds no samples (the recording lasts "
                        f"{length:.3f} s from its first sample)")
    return found


def load_recording(path: str | os.PathLike[str]) -> Recording:
    """The whole recording of ``path`` after the evaluator's input checks (:func:`summarise`)."""
    rec = read_whole(path)
    s = summarise(Source(path, rec))
    rec.name = s.name
    return rec
