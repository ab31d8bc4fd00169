"""Where the estimates come from (ROS-free): a :class:`Runner` starts one :class:`Run` per sequence × scenario,
fed the (perturbed) chunks in order. :class:`OfflineRunner` runs the estimators in-process through the node's
:class:`~riann_ros.stream.EstimatorStream`; :class:`RecordedRunner` serves estimates recorded in the bag; the DDS
replay (``--live``) is :class:`riann_ros.evaluation.live.LiveRunner`. See :mod:`riann_ros.evaluation.run`."""

from __future__ import annotations

import time
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from riann_ros.estimators.base import AttitudeEstimator
from riann_ros.estimators.common import BIAS_KEY
from riann_ros.evaluation.results import RECORDED, RunStats
from riann_ros.evaluation.sources import Chunk
from riann_ros.evaluation.specs import EstimatorSpec
from riann_ros.gate import GateConfig
from riann_ros.recording import Recording
from riann_ros.stream import EstimatorStream


class Run(Protocol):
    """One scenario sequence through a set of estimators, fed chunk by chunk."""

    def feed(self, rec: Recording) -> list[NDArray[np.float64]]:
        """The estimates (N, 4) of each estimator for this piece (NaN rows: no estimate)."""
        ...

    def finish(self) -> list[RunStats]: ...


class Runner(Protocol):
    mode: str
    interleaved: bool  # whether several runs may be fed alternately (one pass serves all scenarios)

    def start(self, specs: list[EstimatorSpec], gate: GateConfig, what: str = "") -> Run:
        """A run of ``specs`` behind ``gate``; ``what``: the input and scenario it is, for a runner that reports its
        runs as they go (the live replay's progress)."""
        ...


class _OfflineRun:
    """Each estimator created anew for the run, so that a run's results depend on its input alone, whatever ran
    before it in the process (executors.py: every executor gives the same results). A reset would not do: it keeps
    what belongs to the robot rather than to a run of the filter, e.g. the online magnetometer calibration's latency
    fit (:class:`~riann_ros.estimators.magcal_slot.MagCalSlot`). Creating one costs little (RIANN: ~20 ms)."""

    def __init__(self, specs: list[EstimatorSpec], gate: GateConfig, use_mag: str = "auto") -> None:
        # each spec's magnetometer calibration (parameters, a saved file) as the node takes it at start
        self.streams = [EstimatorStream(spec.create(), gate, spec.mag_config(use_mag), spec.mag_prior)
                        for spec in specs]
        self.stats = [RunStats(cpu_seconds=0.0) for _ in specs]
        self.sigmas: list[NDArray[np.float64] | None] = []  # of the last feed, per estimator (N, 3): σ, state

    def feed(self, rec: Recording) -> list[NDArray[np.float64]]:
        out = []
        self.sigmas = []
        for stream, stats in zip(self.streams, self.stats, strict=True):
            t, cpu = time.perf_counter(), time.process_time()
            q, _accepted = stream.process_batch(rec.stamps_ns, rec.acc, rec.gyr, rec.mag)
            stats.seconds += time.perf_counter() - t
            stats.cpu_seconds += time.process_time() - cpu
            out.append(q)
            self.sigmas.append(np.column_stack([stream.batch_sigma, stream.batch_state]))
        return out

    def finish(self) -> list[RunStats]:
        for stream, stats in zip(self.streams, self.stats, strict=True):
            stats.rejected = {k: int(v) for k, v in stream.gate.rejected.items()}
            stats.resets = {k: int(v) for k, v in stream.gate.resets.items()}
            stats.mag_samples = stream.mag.samples_with_field
            cal = stream.mag_calibration()  # (None with the calibration off: its test is a monitor only)
            stats.mag_converged_after_s = None if cal is None else cal.converged_after_s
            stats.gyro_bias_dps = reported_bias(stream.estimator)
            stats.monitor_trips = {k: int(v) for k, v in stream.monitors.trips.items() if v}
        return self.stats


def reported_bias(est: AttitudeEstimator) -> list[float] | None:
    """The gyro-bias estimate (°/s) an estimator reports in its diagnostics, as the node's ``/diagnostics`` shows
    it; None when it reports none (e.g. Madgwick without its bias front end)."""
    text = est.diagnostics().get(BIAS_KEY)
    if text is None:
        return None
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        return None
    return values if len(values) == 3 else None


class OfflineRunner:
    """Every estimator in-process through the node's :class:`EstimatorStream`."""

    mode = "offline"
    interleaved = True

    def __init__(self, use_mag: str = "auto") -> None:
        self.use_mag = use_mag

    def start(self, specs: list[EstimatorSpec], gate: GateConfig, what: str = "") -> Run:
        return _OfflineRun(specs, gate, self.use_mag)


class _RecordedRun:
    def __init__(self, specs: list[EstimatorSpec]) -> None:
        self.keys = [s.label for s in specs]  # a topic's label is the topic; a file's, its label
        self.sigmas: list[NDArray[np.float64] | None] = []  # of the last feed, per estimate (N, 2)
        self.stats = [RunStats(cpu_seconds=0.0) for _ in specs]

    def feed(self, rec: Recording) -> list[NDArray[np.float64]]:
        recorded = rec.recorded if isinstance(rec, Chunk) else {}
        none = np.full((len(rec), 4), np.nan)
        rows = [recorded.get(k, none) for k in self.keys]
        # a topic's rows carry the σ of its recorded covariance after the quaternion (NaN: none); a file's do not
        self.sigmas = [r[:, 4:6] if r.shape[1] >= 6 and np.isfinite(r[:, 4]).any() else None for r in rows]
        return [r[:, :4] for r in rows]

    def finish(self) -> list[RunStats]:
        return self.stats


class RecordedRunner:
    """The estimates a user recorded in the bag from their own filter: served per chunk from the source's
    :class:`~riann_ros.evaluation.sources.Chunk` (aligned onto the samples there); none in a piece that has
    none (they exist only for the recording as it is)."""

    mode = RECORDED
    interleaved = True

    def start(self, specs: list[EstimatorSpec], gate: GateConfig, what: str = "") -> Run:
        return _RecordedRun(specs)


class Joined:
    """Several runs fed together as one: their estimates and stats in turn."""

    def __init__(self, runs: list[Run]) -> None:
        self.runs = runs

    def feed(self, rec: Recording) -> list[NDArray[np.float64]]:
        return [q for run in self.runs for q in run.feed(rec)]

    def sigmas(self, counts: list[int]) -> list[NDArray[np.float64] | None]:
        """The σ of the last feed per estimator (None: that run reports none); ``counts``: estimators per run."""
        return [s for run, n in zip(self.runs, counts, strict=True) for s in run_sigmas(run, n)]

    def finish(self) -> list[RunStats]:
        return [st for run in self.runs for st in run.finish()]


def run_sigmas(run: Run, n: int) -> list[NDArray[np.float64] | None]:
    """The σ (N, 2; N, 3 with the estimator's heading state, offline) of the last feed of each of the ``n``
    estimators of ``run``: those of an offline run and of the
    covariance recorded with an estimate topic or published by a live node, None for estimates that carry none
    (files, a topic without a covariance, --live-topics attitude topics)."""
    sig = getattr(run, "sigmas", None)
    return list(sig) if isinstance(sig, list) and len(sig) == n else [None] * n
