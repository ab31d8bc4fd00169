"""Stage 1b, the stamps' clock: receive-time stamps told from sample times, and a de-jittered timeline (ROS-free).

A sensor sampling on its own regular clock and stamped on arrival (after a random delivery delay, or read out of
its FIFO a batch at a time) gives stamps that stay within a bounded distance of a regular timeline: the time
spanned by :data:`VR_SPAN` consecutive steps varies only by the delays at its two ends. Samples taken at random
times accumulate their variations like a random walk. The *variance ratio* Var(span) / (``VR_SPAN`` · Var(step))
is therefore ~1 for random sample times and ~1/``VR_SPAN`` for a clock (~0 for FIFO batches). Below
:data:`CLOCK_ON` the stream is ``clocked``: its period is the mean of the last :data:`CLOCK_WINDOW` steps, and
its samples are placed on a timeline advancing by that period, pulled gently toward the stamps
(:data:`CLOCK_GAIN`). A stamp later than the delays can explain follows lost messages: the timeline advances by
the periods lost too, and they are counted so that they do not stretch the period. docs/riann.md, stage 1.
"""

from __future__ import annotations

import math
from collections import deque

VR_SPAN = 16  # steps summed in the variance ratio (FIFO batches up to this size are recognised as a clock)
CLOCK_ON = 0.3  # variance ratio below which the stamps are a regular clock + delivery delays (clock: 1/16,
# FIFO batches of up to 16: at most ~0.2)
CLOCK_OFF = 0.5  # ... and above which they are the sample times again (random sample times: 1)
CLOCK_MIN_SPREAD = 0.02  # std / mean of the steps below which the question does not matter (a FIFO batch of 16
# has a p90 - p10 of 0: the spread is measured by the standard deviation)
CLOCK_WINDOW = 1024  # steps whose mean is the clock period of a clocked stream
CLOCK_MIN_STEPS = 256  # steps seen before judging: ~24 independent spans, P(ratio < 0.3 | random times) ~ 3e-4
CLOCK_GAIN = 1.0 / 256.0  # per sample: how fast the de-jittered timeline of a clocked stream follows its stamps
CLOCK_LOST_SIGMAS = 3.0  # a stamp this many delay deviations (+ half a period) late means lost samples before it


def _moments(total: float, sq: float, n: int) -> tuple[float, float]:
    """Mean and variance of ``n`` values from their running sum and sum of squares."""
    m = total / n
    return m, sq / n - m * m


class _Window:
    """A sliding window of values with running sum and sum of squares."""

    def __init__(self, maxlen: int | None = None) -> None:
        self.v: deque[float] = deque(maxlen=maxlen)
        self.sum = 0.0
        self.sq = 0.0

    def __len__(self) -> int:
        return len(self.v)

    def push(self, x: float) -> None:
        if self.v.maxlen is not None and len(self.v) == self.v.maxlen:
            self.pop()
        self.v.append(x)
        self.sum += x
        self.sq += x * x

    def pop(self) -> None:
        old = self.v.popleft()
        self.sum -= old
        self.sq -= old * old

    def moments(self) -> tuple[float, float]:
        return _moments(self.sum, self.sq, len(self.v))


class Clock:
    """The clock test over the input steps and the timeline (ns) that the samples are placed on."""

    def __init__(self) -> None:
        self.clocked = False
        self.t = 0.0  # ns: the newest sample on the timeline (relative to the first one after a (re)start)
        self.raw = 0.0  # ns: the newest stamp on the same scale (differs from t for a clocked stream)
        self._long = _Window(CLOCK_WINDOW)  # the steps whose mean is the period
        self._lost: deque[int] = deque()  # per step in _long: samples of the clock lost within it
        self._lost_sum = 0
        self._ends: deque[float] = deque(maxlen=VR_SPAN + 1)  # running time at the last VR_SPAN + 1 samples
        self._time = 0.0
        self._spans = _Window(CLOCK_WINDOW - VR_SPAN)  # time spanned by VR_SPAN steps
        # the steps inside every span that covers them (all VR_SPAN of those spans are in _spans): the step
        # variance of the ratio is taken over these, so that a step just in (or about to leave) counts in both
        # parts of the ratio alike; else one lone long step (a few lost messages) looks like a clock for the
        # VR_SPAN samples after it, until the spans that contain it have come in
        self._cov = _Window()

    def start(self) -> None:
        """A new timeline (after a gap or a reset): the next sample is at 0; the statistics stay."""
        self.t = self.raw = 0.0

    # -- statistics --------------------------------------------------------------------------------
    def push(self, dt: float) -> None:
        """Take one input step (s) and judge the stamps again."""
        long = self._long
        if len(long) == CLOCK_WINDOW:
            self._lost_sum -= self._lost.popleft()
        long.push(dt)
        self._lost.append(0)
        ends = self._ends
        if not ends:
            ends.append(self._time)
        self._time += dt
        ends.append(self._time)
        if len(ends) == VR_SPAN + 1:
            spans, cov = self._spans, self._cov
            if len(spans) == CLOCK_WINDOW - VR_SPAN and len(cov):  # the oldest covered step loses its first span
                cov.pop()
            spans.push(ends[-1] - ends[0])
            if len(spans) >= VR_SPAN:  # the step VR_SPAN - 1 before the newest now has all its spans
                cov.push(long.v[-VR_SPAN])
        self._judge()

    def period(self, fallback: float) -> float:
        """Mean step of the last ``CLOCK_WINDOW`` samples, counting the samples lost in between (s): the sample
        clock's period when ``clocked`` (``fallback`` before any step)."""
        long = self._long
        return long.sum / (len(long) + self._lost_sum) if len(long) else fallback

    def delay_spread(self) -> float:
        """Standard deviation (s) of the stamps around the clock: Var(span) = 2 Var(delay)."""
        if len(self._spans) < 2:
            return 0.0
        return math.sqrt(self._span_var() / 2.0)

    def variance_ratio(self) -> float:
        """Var(time spanned by ``VR_SPAN`` steps) / (``VR_SPAN`` · Var(step)) over the last ``CLOCK_WINDOW`` steps;
        1 while it cannot be told (too few steps, steps all equal)."""
        if len(self._cov) < 3 or len(self._spans) < 2:
            return 1.0
        m, var = self._cov.moments()
        if var <= 1e-12 * m * m:
            return 1.0
        return self._span_var() / (VR_SPAN * var)

    def _span_var(self) -> float:
        return max(self._spans.moments()[1], 0.0)

    def _judge(self) -> None:
        if len(self._long) < CLOCK_MIN_STEPS:
            return
        m, var = self._long.moments()
        if var < (CLOCK_MIN_SPREAD * m) ** 2:
            self.clocked = False
            return
        r = self.variance_ratio()
        if r < CLOCK_ON:
            self.clocked = True
        elif r > CLOCK_OFF:
            self.clocked = False

    # -- the timeline ------------------------------------------------------------------------------
    def advance(self, step_ns: float, dejitter: bool, fallback: float) -> float:
        """Place the next sample, ``step_ns`` after the previous stamp, on the timeline; returns its time (ns).
        ``dejitter``: a clocked stream's sample (one period on, see the module docstring); else as stamped."""
        self.raw += step_ns
        if dejitter:
            step_ns = self._clock_step(self.period(fallback) * 1e9)
        self.t += step_ns
        return self.t

    def _clock_step(self, period: float) -> float:
        """The step (ns) of a clocked stream's sample: one clock period (and the whole periods lost, if the stamp is
        later than the delays explain) plus a small pull toward the stamps."""
        dev = self.raw - (self.t + period)
        lost = 0
        if dev > 0.5 * period + CLOCK_LOST_SIGMAS * self.delay_spread() * 1e9:
            lost = round(dev / period)
            self._lost[-1] += lost
            self._lost_sum += lost
        base = (1 + lost) * period
        step = base + CLOCK_GAIN * (dev - lost * period)
        return min(max(step, base - 0.5 * period), base + 0.5 * period)
