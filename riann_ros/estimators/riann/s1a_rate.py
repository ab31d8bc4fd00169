"""Stage 1a, the input rate: a running median of the input steps and the network's grid step (ROS-free).

The network was trained on constant steps of 2–20 ms and runs on a grid of its own (docs/riann.md, "The
pipeline", stage 1). :func:`choose_step` maps an input step to a grid step; :class:`StepTracker` follows the
input step as the median of the last :data:`RATE_WINDOW` steps and switches the grid step only when the
candidate differs by more than :data:`HYSTERESIS` for half a window, so that jitter, drift or a dropout never
make the grid flap. It also says whether the sample times are *jittery* (their steps spread widely), and keeps
the grid step of a jittery stream while it is inside the trained range (such samples sit on no grid).
"""

from __future__ import annotations

import math
from bisect import bisect_left, insort
from collections import deque

DT_MIN = 0.002  # s, 500 Hz: fastest step the network was trained for
STEP_UP = 0.005  # s: slower inputs are up-sampled to a grid step of at most this (200 Hz)
STEP_FAST = 0.005  # s: inputs faster than 500 Hz are averaged in blocks of about this
STEP_SLACK = 0.1  # relative: the up-sampled grid step may exceed STEP_UP by this much (clock drift)
REL_EPS = 1e-6  # relative slack: a 20 ms step from ns stamps is 0.020000000000000004 s
STEP_MAX = STEP_UP * (1.0 + STEP_SLACK) * (1.0 + REL_EPS)  # s: the largest grid step choose_step gives
RATE_WINDOW = 64  # input steps in the running median
HYSTERESIS = 0.1  # relative change of the grid step needed (for window // 2 samples) to switch
MIN_STEPS = 16  # steps seen before the tracker may switch or judge regularity
IRREGULAR_ON = 0.3  # (p90 - p10) / median of the steps above which the sample times are jittery
IRREGULAR_OFF = 0.15  # ... and below which they are regular again


def choose_step(d: float, step_up: float = STEP_UP, step_fast: float = STEP_FAST) -> float:
    """The network's grid step (s) for an input step ``d`` (s): ``d`` itself inside 2 ms … ``STEP_UP`` (+ slack),
    ``d / k`` for slower inputs (integer up-sampling), ``d · k`` for inputs faster than 500 Hz (blocks)."""
    if not d > 0.0 or not math.isfinite(d):
        raise ValueError(f"input step must be positive and finite, got {d}")
    if d < DT_MIN * (1.0 - REL_EPS):
        return d * max(math.ceil(DT_MIN / d - REL_EPS), round(step_fast / d))
    limit = step_up * (1.0 + STEP_SLACK)
    if d <= limit * (1.0 + REL_EPS):
        return d
    return d / math.ceil(d / limit - REL_EPS)


class StepTracker:
    """Running-median input step, the grid step with hysteresis, and whether the sample times are jittery."""

    def __init__(self, first_dt: float, window: int = RATE_WINDOW, hysteresis: float = HYSTERESIS) -> None:
        self.window = window
        self.hysteresis = hysteresis
        self._dts: deque[float] = deque(maxlen=window)
        self._sorted: list[float] = []
        self.median = first_dt
        self.step = choose_step(first_dt)
        self.jittery = False
        self.switches = 0
        self._pending = 0

    @property
    def judged(self) -> bool:
        """Enough steps seen (``MIN_STEPS``) to say whether the sample times are jittery."""
        return len(self._dts) >= min(MIN_STEPS, self.window)

    def push(self, dt: float, input_step: float | None = None, clocked: bool = False) -> bool:
        """Take one input step (s); return True when the grid step switched. ``input_step``: the step the grid is
        chosen for when it is not the median (a clocked stream's period, stage 1b); ``clocked``: the stamps are a
        clock's (a jittery-looking clock still sits on a grid)."""
        dts, s = self._dts, self._sorted
        if len(dts) == self.window:
            del s[bisect_left(s, dts[0])]
        dts.append(dt)
        insort(s, dt)
        n = len(s)
        self.median = s[n // 2]
        if n < min(MIN_STEPS, self.window):
            return False
        spread = (s[(9 * n) // 10] - s[n // 10]) / self.median
        if spread > IRREGULAR_ON:
            self.jittery = True
        elif spread < IRREGULAR_OFF:
            self.jittery = False
        d = self.median if input_step is None else input_step
        if self.jittery and not clocked and DT_MIN * (1.0 - REL_EPS) <= self.step <= STEP_MAX:
            # irregular sample times never sit on any grid: every step inside the trained range serves, and
            # a switch only changes the network's dt mid-stream (a median of 64 jittered steps wanders: 5-15 ms
            # steps would flip a ratio-keeping grid between 5 and 3.7 ms 42 times in 150 s)
            self._pending = 0
            return False
        # the current ratio of grid step to input step, kept while it still fits: a rate drifting
        # across a factor boundary (10 ms ± 1 %) must not flip between 2 and 3 rows per sample
        same = d * round(self.step / d) if self.step >= d else d / round(d / self.step)
        if abs(same / self.step - 1.0) <= self.hysteresis:
            self._pending = 0
            return False
        cand = choose_step(d)
        self._pending += 1
        if self._pending < max(self.window // 2, 1):
            return False
        self.step = cand
        self._pending = 0
        self.switches += 1
        return True
