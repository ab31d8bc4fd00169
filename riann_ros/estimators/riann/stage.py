"""What RIANN's stages pass each other, the one interface they share, and what each does on a restart (ROS-free).

The estimator (:mod:`.estimator`) is a chain of stages. Each is a :class:`Stage`: ``run`` takes one frozen record
(a block of samples, or of the network rows made from them, or the records of the stages before it that it reads)
and returns one; ``restart(cause)`` does what :data:`RESTARTS` says for that stage; ``diagnostics()`` returns its
own ``/diagnostics`` entries. A single sample is a block of one. The records below are the whole contract between
the stages: no stage reads another's attributes. Values that cross a stage carry their unit in their name
(``_s``, ``_ns``, ``_deg``, ``_rad``, ``_rad_s``); a record's documentation gives the unit of the others. The
physics of each stage is in ``docs/riann.md`` ("The pipeline"), which shows the restart table.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from enum import Enum
from typing import NamedTuple, Protocol, TypeVar

from riann_ros.defaults import FALLBACK_DT_S
from riann_ros.estimators.base import Array
from riann_ros.rotations import Quat, Vec

In = TypeVar("In", contravariant=True)
Out = TypeVar("Out", covariant=True)

#: blocks of up to this many samples (or network rows) take the paths made for the node, which calls ``update``
#: with one sample per message: plain floats in stages 4, 5 and 7, preallocated bound buffers in the model (4b).
#: Longer blocks run vectorised; both give the same numbers (the tests hold each fast path against its reference).
SMALL_BLOCK = 4

ZERO3: Vec = (0.0, 0.0, 0.0)

#: s; a first step (of a stream, or of the bias front end's rows) outside this range is not the stream's: stages 1
#: and 3 start from FALLBACK_DT_S instead (the low end is a hundredth of the network's fastest trained step)
FIRST_STEP_RANGE_S = (2e-5, 10.0)

Row6 = Sequence[float]  # acc xyz (m/s²), gyr xyz (rad/s) of a sample or a grid point
Row7 = tuple[float, float, float, float, float, float, float]  # a network row: acc, gyr less the bias, dt (s)


class Cause(Enum):
    """Why the estimator (or a part of it) starts again."""

    HOLE = "hole"  # a stamp step longer than restart_gap (and 4 input steps) but within the gate's max_dt
    GAP = "gap"  # a stamp step longer than the gate's max_dt (EstimatorStream calls on_gap)
    RESET = "reset"  # a clock jump back, an estimator fault, ~/reset or reset(): everything anew


class Stage(Protocol[In, Out]):
    """One stage of the chain: a block in, a block out, and what it does when the stream restarts."""

    NAME: str  # its row in RESTARTS

    def run(self, block: In) -> Out:
        """The stage on a block (one record in, one record out)."""
        ...

    def restart(self, cause: Cause) -> None:
        """What :data:`RESTARTS` says for ``cause`` (GAP or RESET: a hole travels in the blocks, as data)."""
        ...

    def diagnostics(self) -> dict[str, str]:
        """The stage's ``/diagnostics`` entries."""
        ...


# One table: what each stage does on each restart cause (docs/riann.md shows it; a test keeps both the same and
# checks each entry on the stages). A hole is found by the timeline inside a block and travels down the chain in
# the blocks (at its sample, or, for the network, at the row after that sample's rows); a gap and a reset come
# from outside, and the estimator passes them to every stage's restart().
RESTARTS: dict[str, dict[Cause, str]] = {
    "timeline": {
        Cause.HOLE: "the hole's step is taken as stamped, not counted as an input step; sample-model window cleared",
        Cause.GAP: "new timeline from 0, first step not counted; step and clock statistics kept; sample-model "
                   "window cleared",
        Cause.RESET: "anew",
    },
    "grid": {
        Cause.HOLE: "bridged: the rows across the hole are interpolated from the samples on either side",
        Cause.GAP: "history cleared; the grid restarts at the next sample",
        Cause.RESET: "anew",
    },
    "bias": {
        Cause.HOLE: "kept",
        Cause.GAP: "kept (the same sensor)",
        Cause.RESET: "anew",
    },
    "network": {
        Cause.HOLE: "the old state outputs the first row after the hole, a fresh state starts on that row and "
                    "outputs from the next",
        Cause.GAP: "fresh state",
        Cause.RESET: "anew",
    },
    "carry": {
        Cause.HOLE: "kept",
        Cause.GAP: "from the fresh network's first output",
        Cause.RESET: "anew",
    },
    "handover": {
        Cause.HOLE: "starts: the output moves from the gyro bridge to the fresh network",
        Cause.GAP: "ends (a gap has no bridge); the fresh network's σ_f goes to stage 8 until below 0.01°",
        Cause.RESET: "ends",
    },
    "heading": {
        Cause.HOLE: "kept; with a field, re-acquired weighing the bridge (not while the field is rejected); the "
                    "magnetometer calibration's open window dropped",
        Cause.GAP: "kept; with a field, re-acquired without a bridge; the calibration's open window dropped",
        Cause.RESET: "anew (starts at zero, or at the first field); the magnetometer calibration kept (the robot's), "
                     "its open window dropped",
    },
    "uncertainty": {
        Cause.HOLE: "kept; the hand-over's σ and a share of the bridge's are added",
        Cause.GAP: "rate low-pass and spread start again; the heading unknown until a field sets it",
        Cause.RESET: "anew",
    },
}


def restart_table() -> str:
    """:data:`RESTARTS` as the markdown table docs/riann.md shows."""
    causes = {Cause.HOLE: "hole", Cause.GAP: "gap (> max_dt)", Cause.RESET: "clock jump back, fault, reset"}
    lines = ["| stage | " + " | ".join(causes.values()) + " |", "|---|" + "---|" * len(causes)]
    for stage, what in RESTARTS.items():
        lines.append(f"| {stage} | " + " | ".join(what[c] for c in causes) + " |")
    return "\n".join(lines)


def first_step(dt_s: float) -> float:
    """The step (s) a stage starts from, given the first one it sees (:data:`FIRST_STEP_RANGE_S`)."""
    lo, hi = FIRST_STEP_RANGE_S
    return dt_s if lo < dt_s < hi else FALLBACK_DT_S


# -- the blocks, in the order of the chain -----------------------------------------------------------------------
class Samples(NamedTuple):
    """The estimator's input block: per sample its acc and gyr (:data:`Row6`), its stamp step as given (s), that
    step where it is finite and positive, else 0 (the step stages 6–8 integrate over, s), and its field or None
    (``mag`` None: no sample has one)."""

    x: list[Row6]
    dt_s: list[float]
    step_s: list[float]
    mag: list[Vec | None] | None

    @classmethod
    def of(cls, x: list[Row6], dt_s: list[float], mag: list[Vec | None] | None = None) -> Samples:
        """The block of samples ``x`` with steps ``dt_s`` (s) and fields ``mag``."""
        return cls(x, dt_s, [d if math.isfinite(d) and d > 0.0 else 0.0 for d in dt_s], mag)


class GridSpec(NamedTuple):
    """How the grid reads a sample (s1_timeline and s2_grid)."""

    step_s: float  # the grid step T
    box_s: float  # averaging window of a grid value (0: the signal at the grid point)
    means: bool  # the samples are interval means (else point samples, read curved when up-sampled)
    upsampled: bool  # the box is centred on the grid point (else it ends there)
    delay_s: float  # the sample is the signal at its stamp minus this


class Hole(NamedTuple):
    """A hole that ends at sample ``sample`` of a block: its length and the raw gyro at its two ends."""

    sample: int
    length_s: float
    w_before_rad_s: Vec
    w_after_rad_s: Vec


class TimelineBlock(NamedTuple):
    """Stage 1's output: the samples, and per sample its time on the network's timeline (ns from the start of the
    timeline), how the grid reads it, whether the grid starts at it or its step switched at it; the holes that
    end in the block."""

    samples: Samples
    t_ns: list[float]
    spec: list[GridSpec]
    start: list[bool]
    switched: list[bool]
    holes: list[Hole]


class GridBlock(NamedTuple):
    """Stage 2's output: the network rows (raw, before the bias is removed) with their step, the rows where a fresh
    network starts (``forks``: the first row after a hole sample's rows; ``len(rows)``: after the last), and per
    sample the rows it made (``r0`` up to ``r1``, exclusive) and the raw gyro means that move the attitude on: over
    the step from the previous sample (``gyr_delta_rad_s`` over ``delta_s``) and from the last grid point to the
    sample's stamp (``gyr_carry_rad_s`` over ``carry_s``; 0 s: the sample is on the grid point); the holes that end
    in the block."""

    rows: list[Row6]
    row_step_s: list[float]
    forks: list[int]
    r0: list[int]
    r1: list[int]
    gyr_delta_rad_s: list[Vec]
    delta_s: list[float]
    gyr_carry_rad_s: list[Vec]
    carry_s: list[float]
    holes: list[Hole]


class BiasBlock(NamedTuple):
    """Stage 3's output: the rows with the bias removed, and before each row and after the last (M + 1 values) the
    bias estimate and its standard deviation (VQF's, the worst direction)."""

    rows: list[Row7]
    bias_rad_s: list[Vec]
    sigma_rad_s: list[float]


class NetworkIn(NamedTuple):
    """What stage 4 reads: the rows (stage 3) and where fresh states start (stage 2)."""

    grid: GridBlock
    bias: BiasBlock


class NetworkBlock(NamedTuple):
    """Stage 4's output per row: the ensemble attitude (M, 4) and how far the copies' gravity directions spread
    around their mean (M,)."""

    q: Array
    spread_rad: Array


class CarryIn(NamedTuple):
    """What stage 5 reads."""

    grid: GridBlock
    bias: BiasBlock
    net: NetworkBlock


class CarryBlock(NamedTuple):
    """Stage 5's output per sample: the network attitude carried to its stamp (unit), and its bias-corrected gyro
    increment since the previous sample."""

    q: list[Quat]
    delta: list[Quat]


class HandoverIn(NamedTuple):
    """What stage 6 reads: the samples (acc, steps), the holes (stage 2) and the carried attitudes."""

    samples: Samples
    grid: GridBlock
    carry: CarryBlock


class HandoverBlock(NamedTuple):
    """Stage 6's output per sample: the attitude after the hand-over; its inclination's σ while a hole's
    hand-over runs (0 elsewhere: the heading weighs the field with it), and the fresh network's σ while one
    started by a gap is young (0 elsewhere); and per sample that ends a hole the σ of the bridge over it."""

    q: list[Quat]
    blend_sd_deg: list[float]
    fresh_sd_deg: list[float]
    bridge_sd_deg: dict[int, float]


class HeadingIn(NamedTuple):
    """What stage 7 reads: the samples (steps, fields), the gyro increments (stage 5) and the handed-over
    attitudes (stage 6)."""

    samples: Samples
    carry: CarryBlock
    handover: HandoverBlock


class HeadingBlock(NamedTuple):
    """Stage 7's output: the output attitudes (n, 4), w >= 0, and per sample the heading's gain toward the field
    (0: not corrected), the field reference's dip (0 before a field), the σ the online magnetometer calibration's
    estimate adds to the field's heading (0 while the configured calibration is used, or without the online
    calibration), and while the configured calibration is used the σ of the doubt the gyro-aided test leaves
    about it (0 otherwise)."""

    q: Array
    gain: list[float]
    dip_rad: list[float]
    cal_sd_rad: list[float]
    doubt_sd_rad: list[float]


class UncertaintyIn(NamedTuple):
    """What stage 8 reads: everything it models, as the other stages output it."""

    samples: Samples
    grid: GridBlock
    bias: BiasBlock
    net: NetworkBlock
    handover: HandoverBlock
    heading: HeadingBlock


class Uncertainties(NamedTuple):
    """Stage 8's output per sample: the σ of the inclination per axis and of the heading (n, 2), and the model's
    inputs (s8_uncertainty's FEATURES and YAW_FEATURES: what bench/fit_uncertainty.py fits)."""

    sigma_rad: Array
    features: Array
    yaw_features: Array


__all__ = ["RESTARTS", "SMALL_BLOCK", "ZERO3", "BiasBlock", "CarryBlock", "CarryIn", "Cause", "GridBlock",
           "GridSpec", "HandoverBlock", "HandoverIn", "HeadingBlock", "HeadingIn", "Hole", "NetworkBlock",
           "NetworkIn", "Quat", "Row6", "Row7", "Samples", "Stage", "TimelineBlock", "Uncertainties",
           "UncertaintyIn", "Vec", "first_step", "restart_table"]
