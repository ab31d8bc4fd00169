"""The input checks and dt from stamps that stand before every estimator, node and evaluator alike (ROS-free).

:class:`InputGate` decides, per incoming sample, whether it may reach the estimator and with which
dt (:class:`~riann_ros.stream.EstimatorStream` couples it with an estimator). Decided behaviour (documented in
docs/node.md, "Bad input"):

* non-finite acc or gyr → rejected (``non_finite``), state untouched;
* |acc| > ``max_acc`` or |gyr| > ``max_gyr`` → rejected (``out_of_range``), state untouched;
* stamp equal to the previous accepted one → rejected (``stamp_repeat``);
* stamp earlier than the previous one by at most ``max_dt`` → rejected (``stamp_backwards``);
* stamp earlier by more than ``max_dt`` (a bag replayed in a loop, a restarted driver, the ROS clock
  jumping back) → estimator reset (``clock_jump``), the sample re-initialises it;
* stamp later than the previous one by more than ``max_dt`` (a gap) → estimator restart (``gap``:
  :meth:`~riann_ros.estimators.base.AttitudeEstimator.on_gap`, a reset unless the estimator keeps
  what a gap does not change, as RIANN keeps its gyro-bias estimate), the sample re-initialises it;
* the first sample after a (re)start gets dt = 1 / ``nominal_rate``;
* a zero stamp (drivers that do not stamp) → the receive time is used instead, warned once
  (``zero_stamp``); with no receive time (offline) such a sample is rejected;
* a median |acc| between 0.5 and 1.5 over the first accepted samples of a sequence → warned that the
  accelerometer seems to report in g instead of m/s² (``acc_in_g``; once, again only after a later sequence
  looked right); samples are still used as they are. Every (re)start checks anew (a restarted driver may have
  been fixed): :attr:`InputGate.acc_in_g` holds the latest verdict.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from riann_ros.constants import GRAVITY, NS_PER_S
from riann_ros.params import ParamSpec, defaults, find

# rejection reasons
NON_FINITE = "non_finite"
OUT_OF_RANGE = "out_of_range"
STAMP_REPEAT = "stamp_repeat"
STAMP_BACKWARDS = "stamp_backwards"
NO_STAMP = "no_stamp"
ESTIMATOR_FAULT = "estimator_fault"
REJECT_REASONS = (NON_FINITE, OUT_OF_RANGE, STAMP_REPEAT, STAMP_BACKWARDS, NO_STAMP, ESTIMATOR_FAULT)
# reset causes
START = "start"
GAP = "gap"
CLOCK_JUMP = "clock_jump"
RESET_CAUSES = (START, GAP, CLOCK_JUMP)
# one-shot warnings
ZERO_STAMP = "zero_stamp"
ACC_IN_G = "acc_in_g"
G_CHECK_SAMPLES = 50
G_RANGE = (0.5, 1.5)  # a median |acc| at rest inside this is 1 g read as m/s² (9.81 m/s² would be ~10)
CLEAN_CHUNK = 8192  # samples per vectorised gate check in process_batch

WARNING_TEXT = {
    ZERO_STAMP: "IMU messages carry zero header stamps; using the receive time instead. dt will include "
    "transport jitter: fix the driver's stamping if you can.",
    ACC_IN_G: "the accelerometer magnitude is about 1 at rest: it seems to report in g, but "
    f"sensor_msgs/Imu (REP-145) requires m/s². Estimates will be wrong; scale the driver's output by {GRAVITY}.",
}


#: The gate's parameters: the one place of their defaults and ranges (the node declares them from here).
GATE_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec("nominal_rate", 100.0, "Hz; dt assumed for the first sample after a (re)start, when no previous "
              "stamp exists. Set it to your IMU's rate.", min=1.0, max=100000.0, runtime=True),
    ParamSpec("max_dt", 0.5, "s; a stamp gap larger than this, or a jump back larger than this (bag loop, clock "
              "reset), restarts the estimator from the next sample.", min=0.001, max=3600.0, runtime=True),
    ParamSpec("max_acc", 2000.0, "m/s²; samples with a larger acceleration magnitude are rejected as implausible.",
              min=1.0, max=1.0e6, runtime=True),
    ParamSpec("max_gyr", 200.0, "rad/s; samples with a larger angular rate magnitude are rejected as implausible.",
              min=0.1, max=1.0e6, runtime=True),
)
_GATE_DEFAULTS = defaults(GATE_PARAMS)


@dataclass
class GateConfig:
    """Parameters of the input checks (the node exposes them as ROS parameters; see :data:`GATE_PARAMS`)."""

    nominal_rate: float = _GATE_DEFAULTS["nominal_rate"]  # Hz; dt of the first sample after a (re)start
    max_dt: float = _GATE_DEFAULTS["max_dt"]  # s; larger gaps, or jumps back larger than this, restart
    max_acc: float = _GATE_DEFAULTS["max_acc"]  # m/s²; larger magnitudes are rejected as implausible
    max_gyr: float = _GATE_DEFAULTS["max_gyr"]  # rad/s

    def __post_init__(self) -> None:
        for spec in GATE_PARAMS:
            setattr(self, spec.name, spec.validate(getattr(self, spec.name)))

    @classmethod
    def for_rate(cls, rate_hz: float) -> GateConfig:
        """The default gate with ``nominal_rate`` = ``rate_hz``, or the default rate when that is not a valid
        rate (NaN for a one-sample sequence)."""
        spec = find(GATE_PARAMS, "nominal_rate")
        try:
            return cls(nominal_rate=spec.validate(rate_hz))
        except ValueError:
            return cls()


@dataclass
class GateResult:
    accepted: bool
    dt: float = 0.0  # s, for accepted samples
    stamp_ns: int = 0  # effective stamp (receive time for zero stamps)
    reason: str | None = None  # rejection reason
    reset: str | None = None  # reset cause when the estimator must restart before this sample
    warnings: list[str] = field(default_factory=list)  # one-shot warnings raised by this sample


class InputGate:
    """Per-sample input checks and dt computation. Counters feed the node's diagnostics."""

    def __init__(self, config: GateConfig | None = None) -> None:
        self.config = config or GateConfig()
        self.rejected: Counter[str] = Counter()
        self.resets: Counter[str] = Counter()
        self.accepted = 0
        self._warned: set[str] = set()
        self._g_norms: list[float] = []
        self.acc_median: float | None = None  # median |acc| of the latest complete g-units check window
        self._dt_n = 0
        self._dt_sum = self._dt_sq = 0.0
        self._dt_min, self._dt_max = math.inf, -math.inf
        self.restart()

    def restart(self) -> None:
        """Forget the previous stamp: the next accepted sample starts a new sequence."""
        self._last_ns: int | None = None

    @property
    def acc_in_g(self) -> bool:
        """Whether the latest g-units check (the first :data:`G_CHECK_SAMPLES` of the current or last sequence) found
        the accelerometer reporting in g."""
        return self.acc_median is not None and G_RANGE[0] < self.acc_median < G_RANGE[1]

    def _warn(self, key: str, out: list[str]) -> None:
        if key not in self._warned:
            self._warned.add(key)
            out.append(key)

    def check(self, stamp_ns: int, acc: ArrayLike, gyr: ArrayLike, receive_ns: int | None = None) -> GateResult:
        warnings: list[str] = []
        if stamp_ns == 0:
            if receive_ns is None:
                self.rejected[NO_STAMP] += 1
                return GateResult(False, reason=NO_STAMP)
            self._warn(ZERO_STAMP, warnings)
            stamp_ns = receive_ns
        reason, acc_norm = self._sample_verdict(acc, gyr)
        reset = None
        if reason is None:
            reason, reset = self._stamp_verdict(stamp_ns)
        if reason is not None:
            self.rejected[reason] += 1
            return GateResult(False, stamp_ns=stamp_ns, reason=reason, warnings=warnings)
        if reset is None:
            dt = (stamp_ns - self._last_ns) * 1e-9  # type: ignore[operator]
        else:
            dt = 1.0 / self.config.nominal_rate
            self.resets[reset] += 1
            self._g_norms = []  # a new sequence checks the accelerometer's unit anew
        self._accept(stamp_ns, dt, acc_norm, warnings)
        return GateResult(True, dt=dt, stamp_ns=stamp_ns, reset=reset, warnings=warnings)

    def _sample_verdict(self, acc: ArrayLike, gyr: ArrayLike) -> tuple[str | None, float]:
        """(rejection reason or None, |acc|) of one sample's values."""
        # plain floats: this runs once per message in the node
        # (Python floats also keep numpy's overflow warnings out of huge inputs: they just become inf)
        ax, ay, az = (float(v) for v in acc)  # type: ignore[union-attr, arg-type]
        gx, gy, gz = (float(v) for v in gyr)  # type: ignore[union-attr, arg-type]
        sa = ax * ax + ay * ay + az * az
        sg = gx * gx + gy * gy + gz * gz
        if not (math.isfinite(sa) and math.isfinite(sg)):  # NaN or inf in a component, or overflow
            finite = all(math.isfinite(v) for v in (ax, ay, az, gx, gy, gz))
            return (OUT_OF_RANGE if finite else NON_FINITE), math.nan
        na = math.sqrt(sa)
        if na > self.config.max_acc or math.sqrt(sg) > self.config.max_gyr:
            return OUT_OF_RANGE, na
        return None, na

    def _stamp_verdict(self, stamp_ns: int) -> tuple[str | None, str | None]:
        """(rejection reason or None, restart cause or None) of a sample's stamp after the previous one."""
        if self._last_ns is None:
            return None, START
        diff = stamp_ns - self._last_ns
        max_dt_ns = self.config.max_dt * NS_PER_S
        if diff == 0:
            return STAMP_REPEAT, None
        if diff < 0:
            return (STAMP_BACKWARDS, None) if -diff <= max_dt_ns else (None, CLOCK_JUMP)
        return None, (GAP if diff > max_dt_ns else None)

    def _accept(self, stamp_ns: int, dt: float, acc_norm: float, warnings: list[str]) -> None:
        self._last_ns = stamp_ns
        self.accepted += 1
        self._dt_n += 1
        self._dt_sum += dt
        self._dt_sq += dt * dt
        self._dt_min = min(self._dt_min, dt)
        self._dt_max = max(self._dt_max, dt)
        if len(self._g_norms) < G_CHECK_SAMPLES:
            self._g_norms.append(acc_norm)
            if len(self._g_norms) == G_CHECK_SAMPLES:
                self.acc_median = float(np.median(self._g_norms))
                if self.acc_in_g:
                    self._warn(ACC_IN_G, warnings)
                else:
                    self._warned.discard(ACC_IN_G)  # fixed: a later relapse is warned about again

    def check_clean_prefix(
        self, stamps_ns: NDArray[np.int64], acc: NDArray[np.float64], gyr: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """Vectorised :meth:`check` for the leading samples that continue the current sequence cleanly.

        The longest prefix whose samples would all be accepted without a restart or a warning (finite,
        in range, non-zero stamps, each step in (0, ``max_dt``], after the g-units check window) is
        taken at once: the gate's state and counters advance exactly as per-sample checks would, and
        its dts (s) are returned (empty when the first sample needs the per-sample path).
        """
        none = np.empty(0)
        if self._last_ns is None or len(stamps_ns) == 0 or len(self._g_norms) < G_CHECK_SAMPLES:
            return none
        cfg = self.config
        with np.errstate(over="ignore", invalid="ignore"):
            sa = np.einsum("ij,ij->i", acc, acc)
            sg = np.einsum("ij,ij->i", gyr, gyr)
            good = np.isfinite(sa) & np.isfinite(sg) & (np.sqrt(sa) <= cfg.max_acc) & (np.sqrt(sg) <= cfg.max_gyr)
        diffs = np.diff(stamps_ns, prepend=np.int64(self._last_ns))
        good &= (stamps_ns != 0) & (diffs > 0) & (diffs <= cfg.max_dt * NS_PER_S)
        k = len(good) if good.all() else int(np.argmin(good))
        if k == 0:
            return none
        dt = diffs[:k] * 1e-9
        self._last_ns = int(stamps_ns[k - 1])
        self.accepted += k
        self._dt_n += k
        self._dt_sum += float(dt.sum())
        self._dt_sq += float((dt * dt).sum())
        self._dt_min = min(self._dt_min, float(dt.min()))
        self._dt_max = max(self._dt_max, float(dt.max()))
        return dt

    def check_batch(
        self, stamps: NDArray[np.int64], acc: NDArray[np.float64], gyr: NDArray[np.float64]
    ) -> tuple[NDArray[np.bool_], NDArray[np.float64], dict[int, str]]:
        """:meth:`check` over a sequence without receive times: (accepted mask, dts (s), {index where the
        estimator restarts: cause}); clean stretches at once (:meth:`check_clean_prefix`), anything else per
        sample."""
        n = len(stamps)
        accepted = np.zeros(n, dtype=bool)
        dts = np.zeros(n)
        starts: dict[int, str] = {}
        i = 0
        while i < n:
            j = min(n, i + CLEAN_CHUNK)
            clean = self.check_clean_prefix(stamps[i:j], acc[i:j], gyr[i:j])
            if len(clean):
                accepted[i : i + len(clean)] = True
                dts[i : i + len(clean)] = clean
                i += len(clean)
                continue
            r = self.check(int(stamps[i]), acc[i], gyr[i])
            if r.accepted:
                accepted[i] = True
                dts[i] = r.dt
                if r.reset is not None:
                    starts[i] = r.reset
            i += 1
        return accepted, dts, starts

    @property
    def warned(self) -> tuple[str, ...]:
        """The one-shot warnings raised so far (:data:`WARNING_TEXT` keys, sorted)."""
        return tuple(sorted(self._warned))

    def pop_dt_stats(self) -> dict[str, float]:
        """dt statistics (s) since the last call: count, min, mean, max, std; then forget them."""
        n = self._dt_n
        if n == 0:
            return {"count": 0.0}
        mean = self._dt_sum / n
        out = {"count": float(n), "min": self._dt_min, "mean": mean, "max": self._dt_max,
               "std": math.sqrt(max(self._dt_sq / n - mean * mean, 0.0))}
        self._clear_dt_stats()
        return out

    def _clear_dt_stats(self) -> None:
        # running sums, not a list: the gate also runs over hour-long bags offline
        self._dt_n = 0
        self._dt_sum = self._dt_sq = 0.0
        self._dt_min, self._dt_max = math.inf, -math.inf
