"""What RIANN's stages pass each other, and what each does when the stream restarts (ROS-free).

The estimator (:mod:`.estimator`) is a chain of stages, each a class with one small interface: ``run`` takes a
block of samples (or of the network rows made from them) and returns a block; ``restart(cause)`` does what
:data:`RESTARTS` says for that stage; ``diagnostics()`` returns its own ``/diagnostics`` entries. A single sample
is a block of one. The physics of each stage is in ``docs/riann.md`` ("The pipeline"), which shows the same table.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum

from riann_ros.rotations import Quat, Vec


class Cause(Enum):
    """Why the estimator (or a part of it) starts again."""

    HOLE = "hole"  # a stamp step longer than restart_gap (and 4 input steps) but within the gate's max_dt
    GAP = "gap"  # a stamp step longer than the gate's max_dt (EstimatorStream calls on_gap)
    RESET = "reset"  # a clock jump back, an estimator fault, ~/reset or reset(): everything anew


# One table: what each stage does on each restart cause (docs/riann.md shows it; test_riann_stages checks both
# say the same). A hole is found by the timeline inside a block and travels down the chain as an event at its
# sample (or, for the network, at the row after that sample's rows); a gap and a reset come from outside.
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
        Cause.HOLE: "a fresh state runs beside the old one from the row after the hole and replaces it after "
                    "restart_warmup",
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
        Cause.HOLE: "kept; with a field, re-acquired weighing the bridge (not while the field is rejected)",
        Cause.GAP: "kept; with a field, re-acquired without a bridge",
        Cause.RESET: "anew (starts at zero, or at the first field)",
    },
}



def restart_table() -> str:
    """:data:`RESTARTS` as the markdown table docs/riann.md shows."""
    causes = {Cause.HOLE: "hole", Cause.GAP: "gap (> max_dt)", Cause.RESET: "clock jump back, fault, reset"}
    lines = ["| stage | " + " | ".join(causes.values()) + " |", "|---|" + "---|" * len(causes)]
    for stage, what in RESTARTS.items():
        lines.append(f"| {stage} | " + " | ".join(what[c] for c in causes) + " |")
    return "\n".join(lines)


# grid step T (s), box width (s), interval means, up-sampled (the box is centred on the grid point, else it ends
# there; point samples are read curved), sample delay D (s: the sample is the signal at its stamp minus D); see
# s1_timeline and s2_grid
GridSpec = tuple[float, float, bool, bool, float]
Row6 = tuple[float, ...]  # acc xyz (m/s²), gyr xyz (rad/s) of a sample or a grid point


@dataclass(slots=True)
class Hole:
    """A hole that ends at sample ``index`` of a block: its length and the raw gyro at its two ends."""

    index: int
    seconds: float
    w_before: Vec
    w_after: Vec


@dataclass(slots=True)
class TimelineBlock:
    """Stage 1's output, per sample: its time on the network's timeline (ns), how the grid reads it, whether the
    grid step switched at it or the grid starts at it; and the holes that end in the block."""

    t: list[float] = field(default_factory=list)
    spec: list[GridSpec] = field(default_factory=list)
    start: list[bool] = field(default_factory=list)
    switched: list[bool] = field(default_factory=list)
    holes: list[Hole] = field(default_factory=list)


@dataclass(slots=True)
class GridBlock:
    """Stage 2's output: the network rows (raw, before the bias is removed) with their step, where a fresh network
    starts (row position, grid step there), and per sample the rows it made (``r0`` up to ``r1``, exclusive) and
    the raw gyro means that move the attitude on: over the step from the previous sample (``g_delta`` over
    ``s_delta`` s) and from the last grid point to the sample's stamp (``g_carry`` over ``s_carry`` s; 0 s: the
    sample is on the grid point)."""

    rows: list[Row6] = field(default_factory=list)
    steps: list[float] = field(default_factory=list)
    forks: list[tuple[int, float]] = field(default_factory=list)
    r0: list[int] = field(default_factory=list)
    r1: list[int] = field(default_factory=list)
    g_delta: list[Vec] = field(default_factory=list)
    s_delta: list[float] = field(default_factory=list)
    g_carry: list[Vec] = field(default_factory=list)
    s_carry: list[float] = field(default_factory=list)


__all__ = ["RESTARTS", "Cause", "GridBlock", "GridSpec", "Hole", "Quat", "Row6", "TimelineBlock", "Vec",
           "restart_table"]
