"""Input loss: the share of the IMU's samples that did not arrive, from the stamps against the nominal rate
(ROS-free).

A sensor at ``nominal_rate`` produces that many samples per second of its stamps, whatever their jitter, bursts
(a FIFO read out) or delivery: over the stamps' elapsed time the samples expected are ``elapsed × nominal_rate``,
and those that arrived are counted. Both sums forget with the time constant :data:`WINDOW_S`, so the share follows
the last tens of seconds: ``lost = 1 − received / expected``. Above :data:`WARN_SHARE` the monitor WARNs (each hole
is a restart of RIANN's network and a gyro bridge across it, and a classical filter integrates the gyro over it).
A gap longer than ``max_dt`` (a restart of the estimator) counts as lost time too. The estimate's σ is the
estimator's own (RIANN's holes are in its model); nothing else changes. The share is only as right as
``nominal_rate``: a wrong one is a warning of its own (the node's stamp-rate check).
"""

from __future__ import annotations

import math

from riann_ros.monitors.base import Level, Verdict

#: s; the window (time constant) over which the lost share is measured
WINDOW_S = 10.0
#: the lost share above which the monitor warns: one sample in twenty
WARN_SHARE = 0.05
#: the share is judged once this many samples are expected in the window (not on the first few samples)
MIN_EXPECTED = 50.0


class InputLossMonitor:
    """The lost share of the IMU's samples (module docstring); :meth:`step` per accepted sample."""

    NAME = "input loss"

    def __init__(self, nominal_rate_hz: float) -> None:
        self.nominal_rate_hz = nominal_rate_hz
        self.last_ns: int | None = None
        self.expected = 0.0  # forgotten sums (samples)
        self.received = 0.0
        self.expected_total = 0.0  # the same, not forgotten
        self.received_total = 0

    def step(self, stamp_ns: int) -> None:
        """One accepted sample at ``stamp_ns``: its step from the one before (a gap included; the first sample and
        one after a clock jump back count one step of the nominal rate)."""
        last, self.last_ns = self.last_ns, stamp_ns
        dt = (stamp_ns - last) * 1e-9 if last is not None and stamp_ns > last else 1.0 / self.nominal_rate_hz
        f = math.exp(-dt / WINDOW_S)
        expected = dt * self.nominal_rate_hz
        self.expected = f * self.expected + expected
        self.received = f * self.received + 1.0
        self.expected_total += expected
        self.received_total += 1

    @property
    def lost_total(self) -> float:
        """Samples lost in all (expected less received since the start, at least 0)."""
        return max(0.0, self.expected_total - self.received_total)

    @property
    def share(self) -> float:
        """The lost share over the window (0 while fewer than MIN_EXPECTED samples are expected)."""
        if self.expected < MIN_EXPECTED:
            return 0.0
        return max(0.0, 1.0 - self.received / self.expected)

    def verdict(self) -> Verdict:
        s = self.share
        if s <= WARN_SHARE:
            return Verdict(self.NAME)
        return Verdict(self.NAME, Level.WARN,
                       f"{100.0 * s:.0f} % of the IMU's samples lost over the last {WINDOW_S:.0f} s (stamps against "
                       f"nominal_rate {self.nominal_rate_hz:g} Hz; {self.lost_total:.0f} lost in all): a slow or "
                       "overloaded transport or subscriber (check the QoS depth, the network, the CPU load)")
