"""Stage 1, the timeline: where each input sample sits in time for the network, and how the grid reads it (ROS-free).

Per sample, in this order: a step longer than ``restart_gap`` (and than :data:`HOLE_STEPS` median steps) is a
*hole* (messages lost while the sensor moved; it travels down the chain as an event); any other step feeds the
clock test (1b, :mod:`.s1b_clock`) and the rate tracker (1a, :mod:`.s1a_rate`), which may switch the grid step;
the sample is placed on the timeline (as stamped, or de-jittered for a clocked stream); the gyro shows the
sample-model test (1c, :mod:`.s1c_sample_model`) where the sample sits. Its output says, per sample, its time and
the :data:`~.stage.GridSpec` the grid (stage 2) reads it with. docs/riann.md, stage 1.
"""

from __future__ import annotations

from riann_ros.estimators.riann.s1a_rate import REL_EPS, StepTracker
from riann_ros.estimators.riann.s1b_clock import Clock
from riann_ros.estimators.riann.s1c_sample_model import SampleModelTest
from riann_ros.estimators.riann.stage import ZERO3, Cause, GridSpec, Hole, Samples, TimelineBlock, Vec, first_step

HOLE_STEPS = 4.0  # a hole is also longer than this many median input steps
SAMPLE_DELAY = 0.25  # input steps: an up-sampled regular stream's sample is read as the signal this long before
# its stamp (point samples sit at 0, interval means and a MEMS low-pass at about half a step: a quarter halves the
# worst timing error of either; docs/riann.md, stage 1, "Sample delay")
UPSAMPLED = 1.5  # an input step this many grid steps or more is up-sampled (integer ratios: 2, 3, …)


class Timeline:
    """Stage 1 (see the module docstring)."""

    NAME = "timeline"

    def __init__(self, restart_gap_s: float, input_model: str, sample_delay: float = SAMPLE_DELAY) -> None:
        self.restart_gap_s = restart_gap_s
        self.forced = None if input_model == "auto" else input_model == "means"  # None: judged from the stream
        self.sample_delay = sample_delay if input_model == "auto" else 0.0
        self.restart(Cause.RESET)

    def restart(self, cause: Cause) -> None:
        if cause is Cause.RESET:
            self.steps: StepTracker | None = None
            self.clock = Clock()
            self.model = SampleModelTest()
            self._w_prev: Vec = ZERO3
        else:  # GAP: the stamps start again from 0
            self.model.clear_window()
        self._started = False

    # -- what the grid needs to know ---------------------------------------------------------------
    @property
    def irregular(self) -> bool:
        """The samples are read as taken at irregular times (jittery, or set to interval means)."""
        if self.forced is not None:
            return self.forced
        return self.steps is not None and self.steps.jittery

    @property
    def means(self) -> bool:
        """Read the samples as interval means (else as point samples); a set model holds regardless."""
        if self.forced is not None:
            return self.forced
        return self.irregular and not self.clock.clocked and not self.model.points

    @property
    def input_step(self) -> float:
        """The input step the grid is chosen for (s): the clock's period when clocked, else the median."""
        steps = self.steps
        assert steps is not None
        return self.clock.period(steps.median) if self.clock.clocked else steps.median

    def box_width(self) -> float:
        """Averaging window (s) of a grid value: 0 = the signal at the grid point, else its mean over that much time
        around or before it. Up-sampled (T < d), the mean over the grid cell centred on the grid point (the step
        signal of interval means, the curve through point samples). Blocks (T = k·d): point samples, the mean over
        T − d (the k samples of the block); interval means, the whole cell. T = d: the sample itself."""
        assert self.steps is not None
        d, step = self.input_step, self.steps.step
        if self.upsampled:
            return step
        if step > d * (1.0 + REL_EPS):  # blocks
            return step if self.means else step - d
        return 0.0

    @property
    def upsampled(self) -> bool:
        """The grid step is shorter than the input step: several rows per sample, each over a cell centred on its
        grid point (the box width is the grid step)."""
        assert self.steps is not None
        return self.steps.step < self.input_step * (1.0 - REL_EPS)

    def delay(self) -> float:
        """How long before its stamp a sample is read (s): ``sample_delay`` input steps for a regular stream (or a
        clock's) that the grid up-samples, read with ``input_model`` auto; else 0: samples fed straight in (a
        quarter of a step of 5.5 ms or less is small), jittery sample times (the sample-model test finds what
        they are), a set model, and the first ``MIN_STEPS`` steps (before the stream is judged regular)."""
        steps = self.steps
        assert steps is not None
        if self.sample_delay == 0.0 or not steps.judged or (steps.jittery and not self.clock.clocked):
            return 0.0
        d = self.input_step
        # up-sampled: the grid takes an integer number (>= 2) of rows per input step. A clocked stream fed straight in
        # has a grid step (the running median of its jittered stamps) hovering around its period, a hair above or
        # below it: compared directly, the two would switch the delay on and off from sample to sample.
        return self.sample_delay * d if d > UPSAMPLED * steps.step else 0.0

    def spec(self) -> GridSpec:
        assert self.steps is not None
        return GridSpec(self.steps.step, self.box_width(), self.means, self.upsampled, self.delay())

    # -- the stage ---------------------------------------------------------------------------------
    def run(self, block: Samples) -> TimelineBlock:
        t_ns: list[float] = []
        spec: list[GridSpec] = []
        starts: list[bool] = []
        switches: list[bool] = []
        holes: list[Hole] = []
        clock, model = self.clock, self.model
        for k, (xk, d) in enumerate(zip(block.x, block.dt_s, strict=True)):
            w = (xk[3], xk[4], xk[5])
            hole = switched = False
            start = not self._started
            if start:
                self._start(d)
                t = 0.0
            else:
                steps = self.steps
                assert steps is not None
                gap = self.restart_gap_s
                if gap > 0.0 and d > gap and d > HOLE_STEPS * steps.median:
                    hole = True
                    holes.append(Hole(k, d, self._w_prev, w))
                else:
                    clock.push(d)
                    switched = steps.push(d, clock.period(steps.median) if clock.clocked else None, clock.clocked)
                t = clock.advance(float(round(d * 1e9)), clock.clocked and not hole, steps.median)
            if hole:
                model.clear_window()
            model.push(t, w, self.forced is None and self.irregular and not clock.clocked)
            self._w_prev = w
            t_ns.append(t)
            spec.append(self.spec())
            starts.append(start)
            switches.append(switched)
        return TimelineBlock(block, t_ns, spec, starts, switches, holes)

    def _start(self, dt: float) -> None:
        """The first sample after a reset or a gap: the rate tracker starts at its step (or keeps its estimate)."""
        if self.steps is None:
            self.steps = StepTracker(first_step(dt))
        self.clock.start()
        self._started = True

    def diagnostics(self) -> dict[str, str]:
        if self.steps is None:
            return {}
        model = "interval means" if self.means else "point samples"
        return {
            "network rate (Hz)": f"{1.0 / self.steps.step:.1f}",
            "input model": model if self.forced is None else model + " (set)",
            "input stamps": "regular clock + delivery jitter" if self.clock.clocked else "sample times",
        }
