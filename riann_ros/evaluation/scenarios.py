"""The paper's evaluation scenarios as a chunk-by-chunk transform of a recording (ROS-free).

Paper, section "Performance Evaluation":

- ``restrictive`` — the recording from its first sample (with its initial rest), with the gyroscope
  turn-on bias removed: the mean gyro over the *initial rest* is subtracted from the whole sequence.
  The rest is looked for among the samples before the first scored sample (before BROAD's first
  ``movement`` sample) and detected from the signals (:mod:`~riann_ros.evaluation.rest`: the longest
  stretch of ≥ 1.5 s where gyro and accelerometer are still), not assumed: a sensor that moves there
  gives no rest. No rest found (or a recording whose first sample is already scored): nothing is removed,
  and the evaluator warns. ``--rest START:END`` gives the rest by hand.
- ``partially-restrictive`` — ``restrictive`` plus a constant gyro bias per axis drawn from
  N(0, (0.5 °/s)²); the generator is seeded per sequence from ``seed`` and the sequence name
  (:func:`sequence_seed`), so every estimator, scenario and rate sees the same bias.
- ``realistic`` — the ``partially-restrictive`` signals (de-biased, plus the same random bias; the
  paper: "the same gyroscope bias as in the partially restrictive scenario") with the initial rest cut
  away: the sequence starts at the first scored sample, in motion.
- ``as-recorded`` (not in the paper) — the recording exactly as it is: no bias removed, none added,
  estimators run from the first sample, scored on the score mask. What a user's own bag is.

A :class:`ScenarioPlan` is made from the source's :class:`~riann_ros.evaluation.first_pass.Summary` and
applied to each chunk in turn (:meth:`ScenarioPlan.apply`), so a bag never has to be held whole.
"""

from __future__ import annotations

import hashlib
from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import NDArray

from riann_ros.evaluation.first_pass import Summary, summarise
from riann_ros.evaluation.sources import Chunk, Source
from riann_ros.gate import GateConfig
from riann_ros.recording import Recording

RESTRICTIVE = "restrictive"
PARTIAL = "partially-restrictive"
REALISTIC = "realistic"
AS_RECORDED = "as-recorded"
SCENARIOS = (RESTRICTIVE, PARTIAL, REALISTIC, AS_RECORDED)
PAPER_SCENARIOS = (RESTRICTIVE, PARTIAL, REALISTIC)
BIAS_STD_DPS = 0.5  # °/s, paper: N(0, 0.5 °/s) per axis
STAMP_OFFSET_NS = 1_000_000_000  # added when a sequence starts at stamp ≤ 0 (the gate rejects stamp 0)

DEFINITIONS = {
    RESTRICTIVE: "from the first sample; mean gyro over the initial rest (detected before the first scored sample, "
    "see rest_definition; or given with --rest) subtracted; no rest found: nothing subtracted",
    PARTIAL: "restrictive + constant gyro bias per axis ~ N(0, 0.5 deg/s), seeded per sequence "
    "(sha256 of '<seed>:<sequence name>')",
    REALISTIC: "partially-restrictive signals (same bias) starting at the first scored sample",
    AS_RECORDED: "the recording as it is from its first sample: no bias removed or added",
}


def parse_scenarios(text: str) -> list[str]:
    items = [s.strip().lower() for s in text.split(",") if s.strip()]
    if items == ["all"]:
        return list(SCENARIOS)
    if items == ["paper"]:
        return list(PAPER_SCENARIOS)
    aliases = {"partial": PARTIAL, "partially_restrictive": PARTIAL, "as_recorded": AS_RECORDED, "raw": AS_RECORDED}
    out = []
    for s in items:
        s = aliases.get(s, s)
        if s not in SCENARIOS:
            raise ValueError(f"unknown scenario {s!r}; known: {', '.join(SCENARIOS)}, paper (the first three), all")
        if s not in out:
            out.append(s)
    if not out:
        raise ValueError("no scenarios given")
    return out


def sequence_seed(seed: int, name: str) -> int:
    """Deterministic per-sequence seed from the global seed and the sequence name (sha256)."""
    h = hashlib.sha256(f"{int(seed)}:{name}".encode()).digest()
    return int.from_bytes(h[:8], "little")


def random_bias(seed: int, name: str) -> NDArray[np.float64]:
    """The constant gyro bias (rad/s, 3 axes) of the partially-restrictive and realistic scenarios."""
    rng = np.random.default_rng(sequence_seed(seed, name))
    return np.radians(rng.normal(0.0, BIAS_STD_DPS, 3))


@dataclass
class ScenarioInfo:
    scenario: str
    start_index: int  # first sample of the scenario sequence in the (resampled) recording
    rest_samples: int  # samples of the rest whose mean gyro is the turn-on bias (0: no rest)
    bias_removed_dps: list[float]  # mean gyro over the rest (°/s), subtracted
    bias_added_dps: list[float]  # random bias (°/s), added
    unscored_samples: int = 0  # samples before the first scored sample (where the rest is looked for)
    rest_source: str = "none"  # "detected", "given" (--rest) or "none" (no rest found: no bias removed)
    rest_start_s: float | None = None  # the rest, seconds from the first sample of the recording
    rest_end_s: float | None = None

    def to_dict(self) -> dict:
        return asdict(self)


class ScenarioPlan:
    """One scenario of one sequence: where it starts, which biases it removes and adds, the stamp shift."""

    def __init__(self, scenario: str, summary: Summary, seed: int = 0) -> None:
        if scenario not in SCENARIOS:
            raise ValueError(f"unknown scenario {scenario!r}")
        self.scenario = scenario
        self.start = summary.i0 if scenario == REALISTIC else 0
        self.removed = np.zeros(3) if scenario == AS_RECORDED else summary.rest.bias
        self.added = random_bias(seed, summary.name) if scenario in (PARTIAL, REALISTIC) else np.zeros(3)
        first = summary.stamp_i0 if self.start else summary.first_stamp
        self.shift = STAMP_OFFSET_NS - first if first <= 0 else 0
        self.first_stamp = first + self.shift  # of the scenario sequence as the estimators see it
        self.length = summary.n - self.start
        rate = summary.rate_from_i0 if self.start else summary.rate_all
        #: the node's gate for this sequence: the sequence's own rate as nominal_rate
        self.gate = GateConfig.for_rate(rate if self.length > 1 else float("nan"))
        self.info = ScenarioInfo(
            scenario=scenario,
            start_index=self.start,
            rest_samples=summary.rest.samples,
            bias_removed_dps=np.degrees(self.removed).round(6).tolist(),
            bias_added_dps=np.degrees(self.added).round(6).tolist(),
            unscored_samples=summary.i0,
            rest_source=summary.rest.source,
            rest_start_s=summary.rest.start_s,
            rest_end_s=summary.rest.end_s,
        )

    def apply(self, chunk: Recording, offset: int) -> Recording | None:
        """The part of ``chunk`` (whose first sample has the global index ``offset``) in this scenario: gyro
        de-biased and biased, stamps shifted off zero (``shift``). Estimates recorded in the bag (a
        :class:`~riann_ros.evaluation.sources.Chunk`) stay only in ``as-recorded``: they belong to the
        recording as it is."""
        k = max(0, self.start - offset)
        if k >= len(chunk):
            return None
        c = chunk.slice(k) if k else chunk
        gyr = c.gyr - self.removed + self.added
        out = Recording(
            stamps_ns=c.stamps_ns + self.shift if self.shift else c.stamps_ns,
            acc=c.acc,
            gyr=gyr,
            quat_ref=c.quat_ref,
            score_mask=c.score_mask,
            name=c.name,
            dataset=c.dataset,
            source=c.source,
            frame_id=c.frame_id,
            meta=c.meta,
            mag=c.mag,
        )
        if self.scenario == AS_RECORDED and isinstance(chunk, Chunk) and chunk.recorded:
            return Chunk.of(out, chunk.recorded)
        return out


def scenario_recording(rec: Recording, scenario: str, seed: int = 0,
                       rest: tuple[float, float] | None = None) -> tuple[Recording, ScenarioInfo]:
    """A whole recording prepared for ``scenario``: the one-chunk case of :class:`ScenarioPlan` (``rest``: given
    by hand, seconds from the first sample)."""
    plan = ScenarioPlan(scenario, summarise(Source(rec.name, rec), rest), seed)
    out = plan.apply(rec, 0)
    if out is None:  # pragma: no cover - summarise guarantees scored samples, so the start is inside
        raise ValueError(f"{rec.name}: empty {scenario} sequence")
    return out, plan.info
