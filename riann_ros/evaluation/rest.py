"""Finding the initial rest from the physics of the signals, chunk by chunk (ROS-free).

The restrictive, partially-restrictive and realistic scenarios remove the gyroscope's turn-on bias: the
mean gyro over a rest before the first scored sample. That span is *not* assumed to be a rest: a sample
is at rest when, after a low-pass filter (2nd-order Butterworth, time constant :data:`REST_TAU_S`, as in
VQF's rest detector),

* the gyro deviates from its low-passed value by less than :data:`REST_GYR_DEV_DPS` (no rotation beyond
  sensor noise),
* every axis of the low-passed gyro is below :data:`REST_GYR_MAX_DPS` (a constant rate larger than any
  plausible turn-on bias is a rotation, not a bias),
* the accelerometer deviates from its low-passed value by less than :data:`REST_ACC_DEV` (no shocks or
  changing accelerations), and
* the low-passed accelerometer's norm is within :data:`REST_ACC_NORM_TOL` of :data:`GRAVITY` (only gravity
  is measured);

a *rest* is a stretch of such samples lasting at least :data:`REST_MIN_S`. The longest rest before the
first scored sample is used (the later one on a tie: the turn-on bias drifts while the sensor warms up);
with none, no bias is removed and the evaluator says so. ``--rest START:END`` gives the rest by hand
(seconds from the first sample) instead.

Everything is computed in one pass over the samples before the first scored one, with the filter state
carried across chunks, so a bag read in chunks gives exactly the rest of the whole recording; memory holds
the gyro of the best and of the current stretch (at most those samples).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from riann_ros.constants import GRAVITY, NS_PER_S
from riann_ros.recording import Recording

#: s, time constant of the low-pass filter; VQF's ``restFilterTau`` (cut-off √2/(2π·0.5 s) ≈ 0.45 Hz:
#: averages sensor noise, keeps the slowest deliberate motions)
REST_TAU_S = 0.5
#: °/s, gyro deviation from its low-passed value; VQF's ``restThGyr``. MEMS gyro noise is ~0.01–0.1 °/s/√Hz,
#: i.e. well below 1 °/s per sample at a few hundred Hz (BROAD's rests: < 1 °/s at 286 Hz, bias included)
REST_GYR_DEV_DPS = 2.0
#: °/s, largest low-passed gyro per axis that counts as a bias; VQF's ``biasClip`` (the largest gyro bias VQF
#: believes in). Calibrated MEMS gyros have turn-on biases well below it (BROAD: ≤ 0.5 °/s); a steady rotation
#: about the vertical (constant gyro, constant acc) is faster than that and must not be taken for a bias
REST_GYR_MAX_DPS = 2.0
#: m/s², accelerometer deviation from its low-passed value; VQF's ``restThAcc`` (noise ~0.01–0.05 m/s²; a hand
#: holding a sensor moves it by more)
REST_ACC_DEV = 0.5
#: m/s², tolerance of ‖acc‖ to standard gravity (:data:`~riann_ros.constants.GRAVITY`) at rest: a consumer
#: accelerometer's offset and scale errors (±50–80 mg per axis in datasheets, BROAD's rests 9.82–9.91 m/s²) plus
#: the local gravity (±0.03 m/s²); a sustained vertical acceleration or a horizontal one above ~4.4 m/s² exceeds it
REST_ACC_NORM_TOL = 1.0
#: s, shortest rest; VQF's ``restMinT``. Shorter quiet spells happen inside motions (turning points); 1.5 s of
#: samples also average the gyro noise to ~0.01 °/s
REST_MIN_S = 1.5

DETECTED = "detected"
GIVEN = "given"
NO_REST = "none"

NO_REST_WARNING = "no rest found before the first scored sample: no bias removed"
DEFINITION = (
    f"longest stretch of >= {REST_MIN_S} s before the first scored sample where, after a 2nd-order Butterworth "
    f"low-pass (tau {REST_TAU_S} s): |gyr - lp(gyr)| < {REST_GYR_DEV_DPS} deg/s, |lp(gyr)| per axis < "
    f"{REST_GYR_MAX_DPS} deg/s, |acc - lp(acc)| < {REST_ACC_DEV} m/s^2, | |lp(acc)| - {GRAVITY} | < "
    f"{REST_ACC_NORM_TOL} m/s^2 (VQF's rest detector thresholds); its mean gyro is the bias removed. "
    "--rest START:END gives it by hand"
)


@dataclass
class Rest:
    """The rest whose mean gyro is the turn-on bias: samples ``[start, stop)`` of the recording."""

    source: str = NO_REST  # DETECTED, GIVEN or NO_REST
    start: int = 0
    stop: int = 0
    start_s: float | None = None  # seconds from the first sample
    end_s: float | None = None  # … of the last rest sample
    gyr_mean: NDArray[np.float64] | None = None  # rad/s (None: no rest)

    @property
    def found(self) -> bool:
        return self.gyr_mean is not None

    @property
    def samples(self) -> int:
        return self.stop - self.start if self.found else 0

    @property
    def bias(self) -> NDArray[np.float64]:
        """The gyro bias to remove (zeros without a rest)."""
        return self.gyr_mean if self.gyr_mean is not None else np.zeros(3)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["gyr_mean"] = None if self.gyr_mean is None else np.degrees(self.gyr_mean).round(6).tolist()
        return d


def parse_rest(text: str) -> tuple[float, float]:
    """``"START:END"`` (seconds from the first sample) → (start, end); ValueError otherwise."""
    parts = text.split(":")
    try:
        if len(parts) != 2:
            raise ValueError
        a, b = float(parts[0]), float(parts[1])
    except ValueError:
        raise ValueError(f"--rest expects START:END in seconds from the first sample, got {text!r}") from None
    if not (math.isfinite(a) and math.isfinite(b) and 0 <= a < b):
        raise ValueError(f"--rest {text}: need 0 <= START < END")
    return a, b


def lowpass_coeffs(rate_hz: float, tau: float = REST_TAU_S) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(b, a) of the 2nd-order Butterworth low-pass with cut-off √2/(2πτ) (VQF's ``filterCoeffs``);
    passthrough when the cut-off exceeds 90 % of the Nyquist frequency."""
    ts = 1.0 / rate_hz
    if not (math.isfinite(ts) and ts > 0) or tau < ts / 2:
        return np.array([1.0, 0.0, 0.0]), np.array([1.0, 0.0, 0.0])
    fc = math.sqrt(2) / (2.0 * math.pi * tau)
    c = math.tan(math.pi * fc * ts)
    d = c**2 + math.sqrt(2) * c + 1
    b0 = c**2 / d
    return np.array([b0, 2 * b0, b0]), np.array([1.0, 2 * (c**2 - 1) / d, (1 - math.sqrt(2) * c + c**2) / d])


class _Stretch:
    """A run of consecutive rest samples: where it starts and ends, and its gyro (kept until the run is known to be
    shorter than the best one, so the mean is that of the whole run in one array, whatever the chunking)."""

    def __init__(self, index: int, stamp: int) -> None:
        self.start = self.stop = index
        self.first = self.last = stamp
        self.gyr: list[NDArray[np.float64]] = []

    def extend(self, stop: int, last: int, gyr: NDArray[np.float64]) -> None:
        self.stop, self.last = stop, last
        self.gyr.append(gyr.copy())

    def mean(self) -> NDArray[np.float64]:
        return np.mean(np.concatenate(self.gyr), axis=0)

    @property
    def seconds(self) -> float:
        return (self.last - self.first) * 1e-9


class RestDetector:
    """The longest rest among samples ``[0, stop)``, fed chunk by chunk (``add``), and an optional rest given by
    hand (``given``: seconds from the first sample), which then wins."""

    def __init__(self, rate_hz: float, stop: int, first_stamp: int, given: tuple[float, float] | None = None) -> None:
        self.b, self.a = lowpass_coeffs(rate_hz)
        self.stop = stop
        self.first_stamp = first_stamp
        self.given = given
        self.given_span: _Stretch | None = None
        self.zi: NDArray[np.float64] | None = None  # (2, 6) filter state of gyr and acc
        self.run: _Stretch | None = None  # the stretch still open at the end of the last chunk
        self.best: _Stretch | None = None
        self.segments: list[Rest] = []  # every rest of at least REST_MIN_S, in order (their gyro means)
        self.n = 0  # samples seen
        self.last_stamp = first_stamp

    @property
    def done(self) -> bool:
        """Whether later chunks cannot change the result."""
        return self.n >= self.stop and (self.given is None or self.last_stamp >= self._ns(self.given[1]))

    def _ns(self, seconds: float) -> int:
        return self.first_stamp + round(seconds * NS_PER_S)

    def add(self, c: Recording) -> None:
        """The next chunk (its first sample follows the last one added)."""
        offset, self.n = self.n, self.n + len(c)
        if len(c):
            self.last_stamp = int(c.stamps_ns[-1])
        if self.given is not None:
            self._add_given(c, offset)
        k = min(len(c), self.stop - offset)
        if k > 0:
            self._add_detect(c.stamps_ns[:k], c.acc[:k], c.gyr[:k], offset)

    def _add_given(self, c: Recording, offset: int) -> None:
        assert self.given is not None
        lo, hi = np.searchsorted(c.stamps_ns, [self._ns(self.given[0]), self._ns(self.given[1])], side="left")
        if hi > lo:
            if self.given_span is None:
                self.given_span = _Stretch(offset + int(lo), int(c.stamps_ns[lo]))
            self.given_span.extend(offset + int(hi), int(c.stamps_ns[hi - 1]), c.gyr[lo:hi])

    def _at_rest(self, acc: NDArray[np.float64], gyr: NDArray[np.float64]) -> NDArray[np.bool_]:
        from scipy.signal import lfilter, lfilter_zi

        x = np.concatenate([gyr, acc], axis=1)
        if self.zi is None:
            self.zi = lfilter_zi(self.b, self.a)[:, None] * x[0][None, :]
        lp, self.zi = lfilter(self.b, self.a, x, axis=0, zi=self.zi)
        dev_g = np.linalg.norm(gyr - lp[:, :3], axis=1)
        dev_a = np.linalg.norm(acc - lp[:, 3:], axis=1)
        return (
            (dev_g < math.radians(REST_GYR_DEV_DPS))
            & (np.abs(lp[:, :3]).max(axis=1) < math.radians(REST_GYR_MAX_DPS))
            & (dev_a < REST_ACC_DEV)
            & (np.abs(np.linalg.norm(lp[:, 3:], axis=1) - GRAVITY) < REST_ACC_NORM_TOL)
        )

    def _add_detect(self, stamps: NDArray[np.int64], acc: NDArray[np.float64], gyr: NDArray[np.float64],
                    offset: int) -> None:
        rest = self._at_rest(acc, gyr)
        edges = np.flatnonzero(np.diff(np.concatenate([[False], rest, [False]]).astype(np.int8)))
        spans = list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))
        if self.run is not None and (not spans or spans[0][0] > 0):
            self._close()
        for a, b in spans:
            if a > 0 or self.run is None:
                self.run = _Stretch(offset + a, int(stamps[a]))
            self.run.extend(offset + b, int(stamps[b - 1]), gyr[a:b])
            if b < len(rest):
                self._close()

    def _close(self) -> None:
        run, self.run = self.run, None
        if run is None or run.seconds < REST_MIN_S:
            return
        self.segments.append(self._rest(run, DETECTED))
        if self.best is None or run.seconds >= self.best.seconds:
            self.best = run

    def result(self) -> Rest:
        """The rest to use: the given one, else the longest detected one, else none."""
        if self.given is not None:
            return self._rest(self.given_span, GIVEN)
        self._close()
        return self._rest(self.best, DETECTED)

    def _rest(self, s: _Stretch | None, source: str) -> Rest:
        if s is None or s.stop <= s.start:
            return Rest()
        return Rest(source=source, start=s.start, stop=s.stop, start_s=round((s.first - self.first_stamp) * 1e-9, 6),
                    end_s=round((s.last - self.first_stamp) * 1e-9, 6), gyr_mean=s.mean())
