"""An estimator behind the input gate: what the ROS nodes run per message and the offline evaluator per sequence
(ROS-free).

:class:`EstimatorStream` couples an :class:`~riann_ros.gate.InputGate` (the input checks and dt from stamps,
docs/node.md "Bad input") with an estimator and the magnetometer wing: the input (:mod:`riann_ros.magcal.input`:
pairing, plausibility, ``use_mag``, the configured calibration) and, for an estimator that uses the field, the front
end it gives the estimator (:class:`~riann_ros.magcal.frontend.MagFrontEnd`: the online calibration, the latency,
the change events), whose prior (the configured or a saved calibration) and outputs the stream manages. Beside them
run the monitors of the input (:mod:`riann_ros.monitors`: the gyro's unit, input loss, the magnetometer's readings
and calibration), whose verdicts go to ``/diagnostics`` and, where one says the estimate is not to be trusted, into
every σ the stream reports. The node base feeds it one message at a time; the evaluator feeds whole sequences through
:meth:`EstimatorStream.process_batch`, which gives the same numbers as the per-sample path. So an offline score is a
score of what the node does.
"""

from __future__ import annotations

import itertools

import numpy as np
from numpy.typing import ArrayLike, NDArray

from riann_ros.estimators.base import AttitudeEstimator
from riann_ros.gate import ESTIMATOR_FAULT, GAP, GateConfig, GateResult, InputGate
from riann_ros.magcal.frontend import FrontEndConfig, MagFrontEnd
from riann_ros.magcal.input import MagConfig, MagInput
from riann_ros.magcal.records import MagCalibration, MagCalPrior, MagCalStatus
from riann_ros.monitors import UNTRUSTED_SD_RAD, Monitor, Monitors
from riann_ros.monitors.field import CalibrationMonitor, FieldMonitor, LagMonitor
from riann_ros.monitors.gyro_units import GyroUnitsMonitor
from riann_ros.monitors.input_loss import InputLossMonitor

__all__ = ["EstimatorStream", "GateConfig", "InputGate"]


class EstimatorStream:
    """A gate in front of an estimator: what the node runs per message, and the evaluator per sequence."""

    def __init__(self, estimator: AttitudeEstimator, config: GateConfig | None = None,
                 mag_config: MagConfig | None = None, mag_prior: MagCalPrior | None = None) -> None:
        """``mag_prior``: where the online magnetometer calibration starts (a saved calibration,
        :meth:`MagCalPrior.from_calibration`); None: the configured ``mag_hard_iron`` / ``mag_soft_iron``. The
        calibration's settings are the estimator's parameters (``mag_calibration``, …)."""
        self.estimator = estimator
        self.gate = InputGate(config)
        #: the magnetometer's front end of an estimator that uses the field (None: a 6D estimator)
        self.front: MagFrontEnd | None = None
        if estimator.USES_MAG:
            timeout = (mag_config or MagConfig()).mag_timeout
            self.front = MagFrontEnd(FrontEndConfig.of(estimator.params, max_lag_s=timeout),
                                     latency=estimator.front_end_latency())
            estimator.take_front_end(self.front)
        self.mag = MagInput(mag_config, raw=self.front is not None and self.front.calibrating)
        self.mag_prior: MagCalPrior | None = None  # the prior the calibration started from
        self.gyro_units = GyroUnitsMonitor()
        self.loss = InputLossMonitor(self.gate.config.nominal_rate)
        self.field_monitor = FieldMonitor(self.mag)
        watch: list[Monitor] = [self.gyro_units, self.loss]
        if estimator.USES_MAG and self.front is not None:
            watch += [self.field_monitor, CalibrationMonitor(self.front), LagMonitor(self.front)]
        self.monitors = Monitors(watch)
        self.configure_mag(self.mag.config, mag_prior)
        # σ (rad) of the inclination per axis and of the heading (:meth:`AttitudeEstimator.sigma`): of the last
        # accepted sample of process() (None: rejected), and per sample of the last process_batch() (NaN: rejected)
        self.sigma: NDArray[np.float64] | None = None
        self.batch_sigma: NDArray[np.float64] = np.empty((0, 2))
        self.batch_state: NDArray[np.float64] = np.empty(0)  # the estimator's heading state (NaN: it says none)

    def configure_mag(self, config: MagConfig, prior: MagCalPrior | None = None) -> None:
        """New magnetometer parameters (the node's run-time change): with the online calibration on, a new prior
        (``prior``, or the configured ``mag_hard_iron`` / ``mag_soft_iron`` when None) restarts it; the same prior
        keeps it."""
        self.mag.config = config
        if self.front is None or not self.front.calibrating:
            return
        new = prior if prior is not None else config.prior()
        if new != self.mag_prior:
            self.mag_prior = new
            self.front.set_prior(new)

    def mag_calibration(self) -> MagCalibration | None:
        """The online calibration in use (what ``~/save_mag_calibration`` writes); None when it is off (its test then
        runs as a monitor only: nothing of it is the robot's calibration)."""
        front = self.front
        return front.calibration() if front is not None and not front.monitoring else None

    def mag_cal_status(self) -> MagCalStatus | None:
        """The online calibration's state for ``/diagnostics``; None when it is off."""
        return self.front.status() if self.front is not None else None

    def reset(self) -> None:
        """Clear the estimator and restart the stamp sequence (the node's ~/reset service)."""
        self.estimator.reset()
        self.gate.restart()
        self.mag.reset()

    def process(
        self, stamp_ns: int, acc: ArrayLike, gyr: ArrayLike, receive_ns: int | None = None,
        mag: ArrayLike | None = None,
    ) -> tuple[NDArray[np.float64] | None, GateResult]:
        """One sample (and the field paired with it, see :mod:`riann_ros.magcal.input`) → (quaternion wxyz or None
        when rejected, the gate's verdict)."""
        self.sigma = None
        r = self.gate.check(stamp_ns, acc, gyr, receive_ns)
        if not r.accepted:
            return None, r
        if r.reset is not None:
            self._restart(r.reset)
        self._watch(r.stamp_ns, acc, gyr, r.dt)
        field = self.mag.prepare(mag) if self.estimator.USES_MAG else None
        q = self.estimator.update(acc, gyr, r.dt, field)
        if not _is_unit(q):
            return None, self._fault(r)
        self.monitors.tick()
        self.sigma = self.monitors.widened(self.estimator.sigma(np.array([field is not None]))[0])
        if self.mag.note(field is not None) and self.mag.config.declination_deg != 0.0:
            q = self.mag.declination_applied(q[None, :], np.ones(1, dtype=bool))[0]
        return q, r

    def _watch(self, stamp_ns: int, acc: ArrayLike, gyr: ArrayLike, dt: float) -> None:
        """An accepted sample into the monitors of the IMU (its unit, its losses)."""
        ax, ay, az = (float(v) for v in acc)  # type: ignore[union-attr, arg-type]
        gx, gy, gz = (float(v) for v in gyr)  # type: ignore[union-attr, arg-type]
        self.gyro_units.step(ax, ay, az, gx, gy, gz, dt)
        self.loss.nominal_rate_hz = self.gate.config.nominal_rate  # (a run-time change of the parameter)
        self.loss.step(stamp_ns)

    def _watch_rows(self, rows: NDArray[np.intp], acc: NDArray[np.float64], gyr: NDArray[np.float64],
                    dts: NDArray[np.float64]) -> NDArray[np.bool_]:
        """:meth:`_watch` and the monitors' verdicts over accepted samples ``rows`` of a batch, one at a time as
        :meth:`process` takes them; per row whether a verdict then says the estimate is not to be trusted."""
        a, g, d, st = acc[rows].tolist(), gyr[rows].tolist(), dts[rows].tolist(), self._stamps[rows].tolist()
        out = np.zeros(len(rows), dtype=bool)
        self.loss.nominal_rate_hz = self.gate.config.nominal_rate
        step, loss, monitors = self.gyro_units.step, self.loss.step, self.monitors
        for k in range(len(rows)):
            (ax, ay, az), (gx, gy, gz) = a[k], g[k]
            step(ax, ay, az, gx, gy, gz, d[k])
            loss(st[k])
            monitors.tick()
            out[k] = monitors.untrusted
        return out

    def _restart(self, cause: str) -> None:
        self.gyro_units.restart()
        if cause == GAP:
            self.estimator.on_gap()
        else:
            self.estimator.reset()
            self.mag.reset()

    def _fault(self, r: GateResult) -> GateResult:
        # Never publish garbage: an estimator output that is not a finite unit quaternion restarts it.
        self.estimator.reset()
        self.mag.reset()
        self.gate.rejected[ESTIMATOR_FAULT] += 1
        r.accepted = False
        r.reason = ESTIMATOR_FAULT
        return r

    def process_batch(
        self, stamps_ns: ArrayLike, acc: ArrayLike, gyr: ArrayLike, mag: ArrayLike | None = None
    ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """A sequence (with the fields paired to its samples, NaN rows = none) → (quaternions (N, 4) with NaN
        rows for rejected samples, accepted mask); their σ in :attr:`batch_sigma`.

        Equal to calling :meth:`process` per sample (the gate runs per sample; the estimator runs
        vectorised over each run of accepted samples between restarts).
        """
        stamps = np.asarray(stamps_ns, dtype=np.int64)
        acc = np.asarray(acc, dtype=float)
        gyr = np.asarray(gyr, dtype=float)
        self._stamps = stamps
        self._fields = self.mag.prepare_batch(mag) if self.estimator.USES_MAG else None
        state = self.mag.state  # of the last sample (a restart inside the sequence must not clear it)
        out = np.full((len(stamps), 4), np.nan)
        self.batch_sigma = np.full((len(stamps), 2), np.nan)
        self.batch_state = np.full(len(stamps), np.nan)
        accepted, dts, starts = self.gate.check_batch(stamps, acc, gyr)
        idx = np.flatnonzero(accepted)
        if len(idx) == 0:
            return out, accepted
        bounds = [*(int(np.searchsorted(idx, s)) for s in starts), len(idx)]
        if bounds[0] != 0:
            bounds.insert(0, 0)  # continuing a sequence begun by an earlier call
        for lo, hi in itertools.pairwise(bounds):
            seg = idx[lo:hi]
            if len(seg) and int(seg[0]) in starts:
                self._restart(starts[int(seg[0])])
            self._run_segment(seg, acc, gyr, dts, out, accepted)
        self.mag.state = state
        return out, accepted

    def _run_segment(self, seg: NDArray[np.intp], acc: NDArray[np.float64], gyr: NDArray[np.float64],
                     dts: NDArray[np.float64], out: NDArray[np.float64], accepted: NDArray[np.bool_]) -> None:
        """The estimator over accepted samples ``seg`` (no restart inside), outputs into ``out``."""
        fields = self._fields
        while len(seg):
            m = None if fields is None else fields[seg]
            q = self.estimator.update_batch(acc[seg], gyr[seg], dts[seg], m)
            bad = ~_rows_unit(q)
            n_ok = int(np.argmax(bad)) if bad.any() else len(seg)
            got: NDArray[np.bool_] = (np.zeros(len(seg), dtype=bool) if m is None
                                      else np.asarray(np.isfinite(m).all(axis=1), dtype=bool))
            untrusted = self._watch_rows(seg[: n_ok + int(bad.any())], acc, gyr, dts)[:n_ok]
            sig = self.estimator.sigma(got)[:n_ok]
            sig[untrusted, :2] = UNTRUSTED_SD_RAD
            self.batch_sigma[seg[:n_ok]] = sig
            state = self.estimator.heading_state()
            if state is not None:
                self.batch_state[seg[:n_ok]] = state[:n_ok]
            if m is not None or self.mag.seen:
                ok: NDArray[np.bool_] = (np.zeros(n_ok, dtype=bool) if m is None
                                         else np.asarray(np.isfinite(m[:n_ok]).all(axis=1), dtype=bool))
                q[:n_ok] = self.mag.declination_applied(q[:n_ok], self.mag.used(ok))
            if not bad.any():
                out[seg] = q
                return
            # as in process(): the faulty sample is dropped and the estimator restarts after it
            out[seg[:n_ok]] = q[:n_ok]
            accepted[seg[n_ok]] = False
            self.estimator.reset()
            self.mag.reset()
            self.gate.rejected[ESTIMATOR_FAULT] += 1
            seg = seg[n_ok + 1 :]


def _is_unit(q: NDArray[np.float64]) -> bool:
    return bool(np.isfinite(q).all() and abs(float(q @ q) - 1.0) < 1e-6)


def _rows_unit(q: NDArray[np.float64]) -> NDArray[np.bool_]:
    return np.isfinite(q).all(axis=1) & (np.abs(np.sum(q * q, axis=1) - 1.0) < 1e-6)
