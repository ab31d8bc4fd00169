"""The stream's own health: what an IMU stream shows without any estimator or reference (ROS-free).

:class:`StreamHealth` is fed the input's chunks as recorded, once, and gives

* the **rate** (1 / median stamp step) and the **jitter**: the steps' standard deviation, smallest and largest,
  in ms;
* the **holes**: steps of at least :data:`HOLE_STEPS` nominal steps, where at least one sample is missing (their
  number, the samples missing, the longest one);
* what the nodes' **input gate** (:class:`~riann_ros.gate.InputGate`, at the stream's rate) would do with it:
  samples rejected per reason, estimator restarts per cause (a gap longer than ``max_dt``, a clock jump), and its
  one-shot warnings (an accelerometer in g, zero stamps), in the words the node logs;
* the **unit checks** of ``riann-bag-convert`` (:func:`riann_ros.datasets.units.check_units`: rate, gravity at
  rest, gyro range, magnetic field) on every chunk, the first finding of each check kept;
* the **rests**: every stretch of at least 1.5 s where the sensor does not rotate, by the criteria of the initial
  rest (:mod:`~riann_ros.evaluation.rest`), each with its mean gyro, which at rest *is* the gyro bias: what an
  estimator's own bias estimate can be held against when there is no reference.

Everything is a running sum or bounded by the longest rest, so a bag of any length is read chunk by chunk.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from riann_ros.evaluation.rest import RestDetector
from riann_ros.gate import RESET_CAUSES, START, WARNING_TEXT, GateConfig, InputGate
from riann_ros.recording import Recording

#: a step at least this many nominal steps long lost at least one sample: a regular stream's steps are one nominal
#: step apart, a jittered one's spread around it (a driver polled at 10/20/30 ms: steps up to 1.5 nominal ones)
HOLE_STEPS = 2.0


class StreamHealth:
    """Rate, jitter, holes, gate verdicts, unit checks and rests of one input, fed chunk by chunk (:meth:`add`)."""

    def __init__(self, rate_hz: float, first_stamp: int, n: int) -> None:
        self.rate_hz = rate_hz
        self.step_ns = 1e9 / rate_hz if rate_hz > 0 and math.isfinite(rate_hz) else math.nan
        self.first_stamp = first_stamp
        self.gate = InputGate(GateConfig.for_rate(rate_hz))
        self.rests = RestDetector(rate_hz, n, first_stamp)
        self.n = self.steps = self.holes = self.missing = 0
        self.sum = self.sq = 0.0
        self.lo, self.hi = math.inf, -math.inf
        self.longest_hole_ns = 0
        self.last: int | None = None
        self.findings: dict[str, str] = {}  # unit check → its first finding

    def add(self, c: Recording) -> None:
        """The next chunk of the recording as it is."""
        if not len(c):
            return
        from riann_ros.datasets.units import check_units

        st = c.stamps_ns
        steps = np.diff(st, prepend=np.int64(self.last)) if self.last is not None else np.diff(st)
        self.last = int(st[-1])
        self.n += len(c)
        if len(steps):
            self.steps += len(steps)
            self.sum += float(steps.sum())
            self.sq += float(np.sum(steps.astype(np.float64) ** 2))
            self.lo, self.hi = min(self.lo, int(steps.min())), max(self.hi, int(steps.max()))
            if math.isfinite(self.step_ns):
                hole = steps >= HOLE_STEPS * self.step_ns
                self.holes += int(hole.sum())
                self.missing += int(np.sum(np.round(steps[hole] / self.step_ns) - 1))
                self.longest_hole_ns = max(self.longest_hole_ns, int(steps[hole].max(initial=0)))
        self.gate.check_batch(st, c.acc, c.gyr)
        self.rests.add(c)
        ok = np.isfinite(c.acc).all(axis=1) & np.isfinite(c.gyr).all(axis=1)  # what the gate lets through
        if ok.sum() > 1:
            finite = Recording(st[ok], c.acc[ok], c.gyr[ok], mag=None if c.mag is None else c.mag[ok], meta=c.meta)
            for f in check_units(finite):
                self.findings.setdefault(f.check, f.message)

    def result(self) -> dict[str, Any]:
        """The health figures (results.json ``sequences[].health``); times in ms (steps) and s (holes, rests)."""
        n = self.steps
        mean = self.sum / n if n else math.nan
        std = math.sqrt(max(self.sq / n - mean * mean, 0.0)) if n else math.nan
        self.rests.result()  # closes the last rest
        return {
            "samples": self.n,
            "rate_hz": self.rate_hz,
            "step_mean_ms": mean * 1e-6,
            "step_std_ms": std * 1e-6,
            "step_min_ms": self.lo * 1e-6 if n else math.nan,
            "step_max_ms": self.hi * 1e-6 if n else math.nan,
            "holes": self.holes,
            "samples_missing": self.missing,
            "longest_hole_s": self.longest_hole_ns * 1e-9,
            "rejected": {k: int(v) for k, v in self.gate.rejected.items() if v},
            "restarts": {k: int(v) for k, v in self.gate.resets.items() if k in RESET_CAUSES and k != START and v},
            "warnings": [WARNING_TEXT[w] for w in self.gate.warned],
            "unit_findings": list(self.findings.values()),
            "rests": [{"start_s": r.start_s, "end_s": r.end_s, "samples": r.samples,
                       "gyr_mean_dps": np.degrees(r.bias).round(4).tolist()} for r in self.rests.segments],
        }
