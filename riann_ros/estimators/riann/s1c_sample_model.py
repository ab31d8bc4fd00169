"""Stage 1c, the sample model: point samples or interval means, told from the gyro (ROS-free).

A regular stream is read as point samples (the value at its stamp, REP-145's "time of the measurement"). A
jittery one (stage 1a) may be either: a sensor read at irregular times (point samples) or a polled, integrating
or decimating one (each sample the mean since the previous one). With regular stamps the two readings differ by
a constant shift that nothing on the IMU alone can see; with irregular stamps the shift changes from sample to
sample, and :class:`SampleModelTest` finds which reading lets the gyro pass smoothly through its samples.
docs/riann.md, stage 1.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence

MODEL_MEMORY = 256  # moving samples: memory of the point-samples-or-interval-means test
MODEL_MIN_RATE = 0.3  # rad/s: only samples taken while the sensor turns at least this fast count (at rest the
# gyro is noise, which both readings fit alike)
MODEL_MIN_SAMPLES = 32  # moving samples before the test decides
MODEL_Z = 3.0  # the mean misfit difference must be this many standard errors from 0 to decide (or turn)

Sample = Sequence[float]


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
