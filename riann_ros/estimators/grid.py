"""A constant-rate grid for RIANN: a robust rate estimate and causal resampling (ROS-free).

RIANN was trained on sequences of constant time step inside 2–20 ms. Real streams are not like that:
stamps jitter, messages drop, sensors run at 25 Hz or 1 kHz. The network therefore runs on its own
uniform time grid ``tau_m = anchor + m·T`` and never sees the input stamps directly:

* :func:`choose_step` picks ``T`` from the input step ``d``: ``d`` itself inside 2 ms … ``STEP_UP``
  (one row per sample, the samples go straight in), ``d / k`` with ``k = ceil(d / STEP_UP)`` for
  slower inputs (integer up-sampling, grid points stay on the samples of a clean stream) and
  ``d · round(STEP_FAST / d)`` for inputs faster than 500 Hz (integer blocks of samples). ``STEP_UP``
  may be exceeded by ``STEP_SLACK`` (10 %): a real 200 Hz or 100 Hz sensor runs a few ‰ off its
  nominal rate, and a strict 5 ms limit would up-sample a 5.0004 ms stream ×2 (and a 10.0004 ms
  stream ×3) instead of feeding it straight in (×2).
* :class:`RateTracker` estimates ``d`` as the running median of the last ``window`` steps and switches
  ``T`` only when the candidate differs by more than ``hysteresis`` (relative) for ``window // 2``
  samples in a row, so jitter or a dropout never makes the grid flap; a stream whose steps spread
  widely ((p90 − p10) / median > ``IRREGULAR_ON``, hysteresis down to ``IRREGULAR_OFF``: *jittery*
  sample times) keeps its grid step while it is inside the trained range, since such samples sit on no
  grid. It also decides the signal model: a regular stream is read as *point samples*; a jittery one as
  *interval means* (each sample the average since the previous one: what a polled, integrating or
  decimating sensor delivers) until :class:`SampleModelTest` finds from the gyro that its samples are
  point samples read at irregular times.
* It also tells *receive-time stamps* from *sample times*. A sensor sampling on its own regular clock and
  stamped on arrival (after a random delivery delay over USB, Bluetooth or a busy host, or read out of
  its FIFO a batch at a time) gives stamps that stay within a bounded distance of a regular timeline:
  the time spanned by ``VR_SPAN`` consecutive steps varies only by the delays at its two ends, however
  long the span. Samples taken at random times (independent intervals) accumulate their variations
  like a random walk. The *variance ratio* Var(sum of L steps) / (L · Var(step)) is therefore about
  1 for random sample times and 2·Var(delay) / (L · 2·Var(delay)) = 1/L for a clock with independent
  delays (~0 for FIFO batches of up to L samples). Below ``CLOCK_ON`` the stream is ``clocked``: its
  samples are regular point samples, its period the mean of the last ``CLOCK_WINDOW`` steps, and the
  estimator integrates them on a de-jittered timeline instead of the stamps.
* :class:`SignalHistory` holds the recent samples as a signal over time — piecewise linear through
  point samples, or piecewise constant over ``(t_{k-1}, t_k]`` for interval means — and gives its
  value or mean over a window. Up-sampled point samples are read *curved*: over ``(t_{k-1}, t_k]``
  the parabola through samples k-2, k-1 and k (still causal), because at 25–50 Hz a line between
  samples cuts the corners of fast rotations. A grid point is computed as soon as a sample at or after it has
  arrived, from samples up to that stamp only: the resampling is causal.

Everything here is plain Python floats: it runs once per input sample, where numpy's per-call
overhead would dominate.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence

DT_MIN = 0.002  # s, 500 Hz: fastest step the network was trained for
DT_MAX = 0.020  # s, 50 Hz: slowest
STEP_UP = 0.005  # s: slower inputs are up-sampled to a grid step of at most this (200 Hz)
STEP_FAST = 0.005  # s: inputs faster than 500 Hz are averaged in blocks of about this
STEP_SLACK = 0.1  # relative: the up-sampled grid step may exceed STEP_UP by this much (clock drift)
REL_EPS = 1e-6  # relative slack: a 20 ms step from ns stamps is 0.020000000000000004 s
STEP_MAX = STEP_UP * (1.0 + STEP_SLACK) * (1.0 + REL_EPS)  # s: the largest grid step choose_step gives
RATE_WINDOW = 64  # input steps in the running median
HYSTERESIS = 0.1  # relative change of the grid step needed (for window // 2 samples) to switch
MIN_STEPS = 16  # steps seen before the tracker may switch or judge regularity
IRREGULAR_ON = 0.3  # (p90 - p10) / median of the steps above which samples are interval means
IRREGULAR_OFF = 0.15  # ... and below which they are point samples again
VR_SPAN = 16  # steps summed in the variance ratio (FIFO batches up to this size are recognised as a clock)
CLOCK_ON = 0.3  # variance ratio below which the stamps are a regular clock + delivery delays (clock: 1/16,
# FIFO batches of up to 16: at most ~0.2)
CLOCK_OFF = 0.5  # ... and above which they are the sample times again (random sample times: 1)
CLOCK_MIN_SPREAD = 0.02  # std / mean of the steps below which the question does not matter (a FIFO batch of 16
# has a p90 - p10 of 0: the spread is measured by the standard deviation)
CLOCK_WINDOW = 1024  # steps whose mean is the clock period of a clocked stream
CLOCK_MIN_STEPS = 256  # steps seen before judging: ~24 independent spans, P(ratio < 0.3 | random times) ~ 3e-4

MODEL_MEMORY = 256  # moving samples: memory of the point-samples-or-interval-means test
MODEL_MIN_RATE = 0.3  # rad/s: only samples taken while the sensor turns at least this fast count (at rest the
# gyro is noise, which both readings fit alike)
MODEL_MIN_SAMPLES = 32  # moving samples before the test decides
MODEL_Z = 3.0  # the mean misfit difference must be this many standard errors from 0 to decide (or turn)

CURVE_MIN_RATIO = 0.5  # the curved signal model needs neighbouring sample steps less than 2x apart

Sample = Sequence[float]


def choose_step(d: float, step_up: float = STEP_UP, step_fast: float = STEP_FAST) -> float:
    """The network's grid step (s) for an input step ``d`` (s); see the module docstring."""
    if not d > 0.0 or not math.isfinite(d):
        raise ValueError(f"input step must be positive and finite, got {d}")
    if d < DT_MIN * (1.0 - REL_EPS):
        return d * max(math.ceil(DT_MIN / d - REL_EPS), round(step_fast / d))
    limit = step_up * (1.0 + STEP_SLACK)
    if d <= limit * (1.0 + REL_EPS):
        return d
    return d / math.ceil(d / limit - REL_EPS)


class SampleModelTest:
    """Tells point samples from interval means in an *irregular* stream, from the gyro alone.

    A point sample is the signal at its stamp ``t_k``; an interval mean is the signal's mean over
    ``(t_{k-1}, t_k]``, i.e. (to second order) its value at the interval's centre ``t_k − d_k/2``. With
    regular stamps the two readings differ by a constant shift that nothing on the IMU alone can see; with
    irregular stamps the shift changes from sample to sample with the interval, so only the right reading
    puts the samples at the times where a smooth signal passes through them. The test predicts each gyro
    sample from its two neighbours on either side (the cubic through them, so that the curvature of fast
    motion between sparse samples does not drown the misplacement), once at the stamps and once at the
    interval centres, and keeps the difference of the squared misfits (means − points), counting only
    samples taken while the sensor turns (``MODEL_MIN_RATE``: at rest both readings fit the noise alike).
    Its mean over an exponential memory of ``MODEL_MEMORY`` samples is compared with its standard error:
    ``points`` becomes True when the mean is ``MODEL_Z`` standard errors above zero, False when it is as far
    below, and stays as it was in between (None until decided: the stream is read as interval means).
    """

    def __init__(self) -> None:
        self.points: bool | None = None
        self._t: deque[float] = deque(maxlen=6)  # the newest stamps (one more than samples: the centres)
        self._w: deque[Sample] = deque(maxlen=5)  # the newest gyro samples
        self._mean = 0.0  # of (misfit read as means) - (misfit read as points)
        self._sq = 0.0  # ... and of its square
        self._n = 0

    def clear_window(self) -> None:
        """Forget the newest samples (a restart, a hole: no interpolation across it); the evidence stays."""
        self._t.clear()
        self._w.clear()

    def push(self, t: float, w: Sample, judge: bool) -> None:
        """Take a sample at stamp ``t`` with gyro ``w``; with ``judge`` add the misfits of the one two before."""
        self._t.append(t)
        self._w.append(w)
        if not judge or len(self._t) < 6:
            return
        ws = self._w
        mid = ws[2]
        if mid[0] * mid[0] + mid[1] * mid[1] + mid[2] * mid[2] < MODEL_MIN_RATE * MODEL_MIN_RATE:
            return
        tp = self._t
        stamps = (tp[1], tp[2], tp[3], tp[4], tp[5])
        centres = tuple((tp[k] + tp[k + 1]) * 0.5 for k in range(5))
        diff = _misfit(centres, ws) - _misfit(stamps, ws)
        self._n += 1
        a = max(1.0 / MODEL_MEMORY, 1.0 / self._n)
        self._mean += a * (diff - self._mean)
        self._sq += a * (diff * diff - self._sq)
        if self._n < MODEL_MIN_SAMPLES:
            return
        var = self._sq - self._mean * self._mean
        if var <= 0.0:
            return
        z = self._mean / math.sqrt(var / min(self._n, 2 * MODEL_MEMORY))
        if z > MODEL_Z:
            self.points = True
        elif z < -MODEL_Z:
            self.points = False


def _moments(total: float, sq: float, n: int) -> tuple[float, float]:
    """Mean and variance of ``n`` values from their running sum and sum of squares."""
    m = total / n
    return m, sq / n - m * m


def _misfit(t: Sequence[float], w: Sequence[Sample]) -> float:
    """Squared distance of the middle of five samples ``w`` (at times ``t``) from the cubic through the other
    four, at its time."""
    x = t[2]
    others = (0, 1, 3, 4)
    pred = [0.0, 0.0, 0.0]
    for i in others:
        li = 1.0
        for j in others:
            if j != i:
                den = t[i] - t[j]
                if den == 0.0:
                    return 0.0
                li *= (x - t[j]) / den
        wi = w[i]
        pred[0] += li * wi[0]
        pred[1] += li * wi[1]
        pred[2] += li * wi[2]
    m = w[2]
    return (m[0] - pred[0]) ** 2 + (m[1] - pred[1]) ** 2 + (m[2] - pred[2]) ** 2


class RateTracker:
    """Running-median input step, grid step with hysteresis, and the signal model (see module doc)."""

    def __init__(self, first_dt: float, window: int = RATE_WINDOW, hysteresis: float = HYSTERESIS,
                 means: bool | None = None) -> None:
        self.window = window
        self.forced = means  # None: decide the signal model from the stamps' spread
        self.hysteresis = hysteresis
        self._dts: deque[float] = deque(maxlen=window)
        self.median = first_dt
        self.step = choose_step(first_dt)
        self.irregular = bool(means)
        self.jittery = False  # the steps spread widely (irregular sample times), whatever the set signal model
        self.clocked = False  # stamps = a regular sample clock + delivery delays (see variance_ratio)
        self.model_test = SampleModelTest()  # point samples or interval means, for irregular streams
        self.switches = 0
        self._pending = 0
        self._long: deque[float] = deque(maxlen=CLOCK_WINDOW)
        self._long_sum = 0.0  # running sums over _long: steps and their squares
        self._lost: deque[int] = deque()  # per step in _long: samples of the clock lost within it (count_lost)
        self._lost_sum = 0
        self._long_sq = 0.0
        self._ends: deque[float] = deque(maxlen=VR_SPAN + 1)  # running time at the last VR_SPAN + 1 samples
        self._time = 0.0
        self._spans: deque[float] = deque(maxlen=CLOCK_WINDOW - VR_SPAN)  # time spanned by VR_SPAN steps
        self._span_sum = 0.0
        self._span_sq = 0.0
        # the steps inside every span that covers them (all VR_SPAN of those spans are in _spans): the step
        # variance of the ratio is taken over these, so that a step just in (or about to leave) counts in
        # both parts of the ratio alike; else one lone long step (a few lost messages) looks like a clock for
        # the VR_SPAN samples after it, until the spans that contain it have come in
        self._cov: deque[float] = deque()
        self._cov_sum = 0.0
        self._cov_sq = 0.0

    @property
    def means(self) -> bool:
        """Read the samples as interval means (else as point samples); a set model holds regardless."""
        if self.forced is not None:
            return self.forced
        return self.irregular and not self.clocked and not self.model_test.points

    @property
    def mean_step(self) -> float:
        """Mean step of the last ``CLOCK_WINDOW`` samples, counting the samples lost in between (s): the sample
        clock's period when ``clocked``."""
        return self._long_sum / (len(self._long) + self._lost_sum) if self._long else self.median

    def count_lost(self, k: int) -> None:
        """The step just taken spans ``k`` lost samples of the clock besides its own (told by the estimator's
        de-jittered timeline), so that the period is not stretched by lost messages."""
        self._lost[-1] += k
        self._lost_sum += k

    def delay_spread(self) -> float:
        """Standard deviation (s) of the stamps around the clock: the time spanned by ``VR_SPAN`` steps varies
        by the delays at its two ends, Var(span) = 2 Var(delay) (an upper bound when samples were lost)."""
        if len(self._spans) < 2:
            return 0.0
        return math.sqrt(self._span_var() / 2.0)

    @property
    def input_step(self) -> float:
        """The input step the grid is chosen for (s): the clock's period when ``clocked``, else the median."""
        return self.mean_step if self.clocked else self.median

    def variance_ratio(self) -> float:
        """Var(time spanned by ``VR_SPAN`` steps) / (``VR_SPAN`` · Var(step)) over the last ``CLOCK_WINDOW``
        steps: ~1 for samples taken at random times (a renewal process: each interval drawn on its own),
        ~1/``VR_SPAN`` for a regular clock stamped after random delivery delays, ~0 for FIFO batches
        (see the module docstring). 1 while it cannot be told (too few steps, steps all equal)."""
        if len(self._cov) < 3 or len(self._spans) < 2:
            return 1.0
        m, var = _moments(self._cov_sum, self._cov_sq, len(self._cov))
        if var <= 1e-12 * m * m:
            return 1.0
        return self._span_var() / (VR_SPAN * var)

    def _span_var(self) -> float:
        """Variance of the time spanned by ``VR_SPAN`` steps (from the running sums; not empty)."""
        return max(_moments(self._span_sum, self._span_sq, len(self._spans))[1], 0.0)

    def _step_moments(self) -> tuple[float, float]:
        """Mean and variance of the last ``CLOCK_WINDOW`` steps (from the running sums; not empty)."""
        return _moments(self._long_sum, self._long_sq, len(self._long))

    def _push_long(self, dt: float) -> None:
        long = self._long
        if len(long) == CLOCK_WINDOW:
            old = long.popleft()
            self._long_sum -= old
            self._long_sq -= old * old
            self._lost_sum -= self._lost.popleft()
        long.append(dt)
        self._lost.append(0)
        self._long_sum += dt
        self._long_sq += dt * dt
        ends = self._ends
        if not ends:
            ends.append(self._time)
        self._time += dt
        ends.append(self._time)
        if len(ends) == VR_SPAN + 1:
            spans, cov = self._spans, self._cov
            if len(spans) == spans.maxlen:
                old = spans.popleft()
                self._span_sum -= old
                self._span_sq -= old * old
                if cov:  # the oldest covered step has lost its first span
                    old = cov.popleft()
                    self._cov_sum -= old
                    self._cov_sq -= old * old
            span = ends[-1] - ends[0]
            spans.append(span)
            self._span_sum += span
            self._span_sq += span * span
            if len(spans) >= VR_SPAN:  # the step VR_SPAN - 1 before the newest now has all its spans
                step = long[-VR_SPAN]
                cov.append(step)
                self._cov_sum += step
                self._cov_sq += step * step

    def push(self, dt: float) -> bool:
        """Take one input step (s); return True when the grid step switched."""
        dts = self._dts
        dts.append(dt)
        self._push_long(dt)
        n = len(dts)
        s = sorted(dts)
        self.median = s[n // 2]
        if n < min(MIN_STEPS, self.window):
            return False
        spread = (s[(9 * n) // 10] - s[n // 10]) / self.median
        self._judge_model(spread)
        self._judge_clock()
        d = self.input_step
        if self.jittery and not self.clocked and DT_MIN * (1.0 - REL_EPS) <= self.step <= STEP_MAX:
            # irregular sample times never sit on any grid: every step inside the trained range serves, and
            # a switch only changes the network's dt mid-stream (a median of 64 jittered steps wanders:
            # 5-15 ms steps flipped a ratio-keeping grid between 5 and 3.7 ms 42 times in 150 s)
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

    def see(self, t: float, gyr: Sample, hole: bool = False) -> None:
        """Show the signal-model test the sample just taken (stamp ``t``, gyro ``gyr``); it judges only while
        the stream is irregular sample times and the model is not set. ``hole``: the sample ends a hole."""
        if hole:
            self.model_test.clear_window()
        self.model_test.push(t, gyr, self.forced is None and self.irregular and not self.clocked)

    def _judge_model(self, spread: float) -> None:
        if spread > IRREGULAR_ON:
            self.jittery = True
        elif spread < IRREGULAR_OFF:
            self.jittery = False
        self.irregular = self.jittery if self.forced is None else self.forced

    def _judge_clock(self) -> None:
        if len(self._long) < CLOCK_MIN_STEPS:
            return
        m, var = self._step_moments()
        if var < (CLOCK_MIN_SPREAD * m) ** 2:
            self.clocked = False
            return
        r = self.variance_ratio()
        if r < CLOCK_ON:
            self.clocked = True
        elif r > CLOCK_OFF:
            self.clocked = False

    def box_width(self) -> float:
        """Averaging window (s) of a grid value: 0 = the signal at the grid point, else its mean over
        that much time before it. Point samples: up-sampled (T < d), the mean over the grid cell
        ``(tau − T, tau]`` — each row summarises its own interval, as a sensor sampling at ``1/T``
        would, instead of carrying the kinks of the linear interpolation; blocks (T = k·d), the mean
        over ``T − d`` (the k samples of the block); T = d, the sample itself. Interval means: the
        whole cell when T spans several samples, else the sample covering the grid point."""
        d = self.input_step
        if self.means:
            return self.step if self.step > d * (1.0 + REL_EPS) else 0.0
        if self.step < d * (1.0 - REL_EPS):
            return self.step
        return self.step - d if self.step > d * (1.0 + REL_EPS) else 0.0


class SignalHistory:
    """Recent samples ``(t, x)`` (t in ns as float, x a 6-vector) read as a continuous signal.

    ``means=False``: linear between samples; ``means=True``: sample k holds over ``(t_{k-1}, t_k]``.
    Before the first sample the signal holds the first value, after the last the last one.
    """

    def __init__(self) -> None:
        self.t: deque[float] = deque()
        self.x: deque[Sample] = deque()

    def __len__(self) -> int:
        return len(self.t)

    def append(self, t: float, x: Sample) -> None:
        self.t.append(t)
        self.x.append(x)

    def clear(self) -> None:
        self.t.clear()
        self.x.clear()

    def trim(self, before: float) -> None:
        """Drop samples no window starting at ``before`` or later can need (keeps two before it: the
        curved model of the interval around ``before`` reads the sample before that interval)."""
        t = self.t
        while len(t) > 3 and t[2] <= before:
            t.popleft()
            self.x.popleft()

    def value(self, tau: float, means: bool) -> list[float]:
        """The signal at ``tau``."""
        t, x = self.t, self.x
        n = len(t)
        k = n - 1
        while k > 0 and t[k - 1] >= tau:  # k = first sample at or after tau (or the last)
            k -= 1
        if means or k == 0 or t[k] <= tau:
            return list(x[k])
        t0, t1 = t[k - 1], t[k]
        s = (tau - t0) / (t1 - t0)
        return [a + s * (b - a) for a, b in zip(x[k - 1], x[k], strict=True)]

    def mean(self, a: float, b: float, means: bool, lo: int = 0, hi: int = 6, curved: bool = False) -> list[float]:
        """Mean of channels ``lo:hi`` over ``(a, b]``; the value at ``b`` when the window is empty (``b <= a``,
        e.g. a width that rounds away next to a stamp in ns)."""
        if not b > a:
            return self.value(b, means)[lo:hi]
        t, x = self.t, self.x
        acc = [0.0] * (hi - lo)
        if a < t[0]:  # before the first sample: its value held
            _add(acc, x[0], lo, min(b, t[0]) - a)
        for k in range(len(t) - 1, 0, -1):
            if t[k] <= a:
                break
            self._add_interval(acc, k, a, b, means, lo, curved)
        if b > t[-1]:  # after the last sample: its value held
            _add(acc, x[-1], lo, b - max(a, t[-1]))
        w = b - a
        return [v / w for v in acc]

    def _add_interval(self, acc: list[float], k: int, a: float, b: float, means: bool, lo: int,
                      curved: bool = False) -> None:
        """Add the integral over ``(a, b] ∩ (t_{k-1}, t_k]`` of the signal model to ``acc``. ``curved``: point
        samples as the parabola through samples k-2, k-1, k (causal: k is the newest sample the interval
        needs) instead of the line through k-1, k, where the three are about evenly spaced."""
        t0, t1 = self.t[k - 1], self.t[k]
        s0, s1 = max(a, t0), min(b, t1)
        if s1 <= s0:
            return
        x0, x1 = self.x[k - 1], self.x[k]
        span = s1 - s0
        if means:
            _add(acc, x1, lo, span)
            return
        h1 = t1 - t0
        m = 0.5 * ((s0 - t0) + (s1 - t0)) / h1
        for j in range(len(acc)):
            acc[j] += (x0[lo + j] + m * (x1[lo + j] - x0[lo + j])) * span
        if not curved or k < 2:
            return
        h0 = t0 - self.t[k - 2]
        lo_ratio = CURVE_MIN_RATIO * (1.0 + REL_EPS)  # a margin: steps exactly 2x apart (10/20 ms) must not
        if not lo_ratio * h1 < h0 < h1 / lo_ratio:  # flip with the rounding of a stamp sum (chunked = whole)
            return  # across a hole or a rate change: no curvature to read
        # p(u) = line + c·u·(u − h1), u = t − t_{k-1}, c fixed by p(−h0) = x_{k-2}
        u0, u1 = s0 - t0, s1 - t0
        w = ((u1**3 - u0**3) / 3.0 - 0.5 * h1 * (u1**2 - u0**2)) / (h0 * (h0 + h1))
        xm = self.x[k - 2]
        for j in range(len(acc)):
            acc[j] += w * (xm[lo + j] - x0[lo + j] + (x1[lo + j] - x0[lo + j]) * h0 / h1)


def _add(acc: list[float], x: Sample, lo: int, span: float) -> None:
    for j in range(len(acc)):
        acc[j] += x[lo + j] * span
