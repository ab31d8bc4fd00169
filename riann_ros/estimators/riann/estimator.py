"""RIANN: the published recurrent network inside a chain of stages that make it work on real streams (ROS-free).

The network was trained on constant steps of 2–20 ms, gyros without a large bias, and estimates inclination
only. Real streams jitter, lose messages, run at 25 Hz or 1 kHz, start with a bias of several °/s, and carry a
magnetometer. The estimator is the chain below, each stage in its own module (``docs/riann.md`` explains each,
with the physics; :data:`~.stage.RESTARTS` says what each does when the stream restarts):

1. :mod:`.s1_timeline` — where each sample sits in time (rate, clock, sample model; holes found here)
2. :mod:`.s2_grid` — the samples resampled onto the network's constant-step grid (the rows)
3. :mod:`.s3_bias` — the gyro bias estimated on the rows and removed
4. :mod:`.s4_network` — the GRU network as an ensemble of rotated copies, a fresh state after a hole
5. :mod:`.s5_carry` — the newest network attitude carried by the gyro to each sample's stamp
6. :mod:`.s6_handover` — after a hole, from the gyro bridge to the fresh network
7. :mod:`.s7_heading` — a heading that follows the gyro, and the magnetometer when there is one
8. :mod:`.s8_uncertainty` — each output's standard deviations (inclination, heading), read-only (:meth:`sigma`)

Each stage is a :class:`~.stage.Stage`: ``run`` takes one record and returns one (:mod:`.stage` defines them all),
so what a stage reads is what it is given here, and nothing else. A gap and a reset reach every stage through its
``restart`` (:data:`~.stage.RESTARTS`); a hole travels in the blocks. One output per input sample, at its stamp.
``update`` is a block of one; ``update_batch`` runs the same stages on the whole block (the network once over all
its rows), so both give the same numbers (within float32 round-off). With ``rate_adaptation`` off stages 1–2 are
replaced by one row per sample with its own dt.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from riann_ros.estimators.base import Array, AttitudeEstimator, ParamSpec
from riann_ros.estimators.bias import front_end_params
from riann_ros.estimators.riann.s1_timeline import SAMPLE_DELAY, Timeline
from riann_ros.estimators.riann.s2_grid import DirectRows, Grid
from riann_ros.estimators.riann.s3_bias import Bias
from riann_ros.estimators.riann.s4_network import MAX_COPIES, Network
from riann_ros.estimators.riann.s4b_model import BatchedModel
from riann_ros.estimators.riann.s5_carry import Carry
from riann_ros.estimators.riann.s6_handover import Handover
from riann_ros.estimators.riann.s7_heading import Heading
from riann_ros.estimators.riann.s8_uncertainty import Uncertainty
from riann_ros.estimators.riann.stage import (
    CarryIn,
    Cause,
    GridBlock,
    HandoverIn,
    HeadingIn,
    NetworkIn,
    Row6,
    Samples,
    Stage,
    Uncertainties,
    UncertaintyIn,
    Vec,
)
from riann_ros.magcal.frontend import FrontEndConfig, LatencySettings, MagFrontEnd
from riann_ros.magcal.input import MAG_CAL_PARAMS


class RiannEstimator(AttitudeEstimator):
    """RIANN with its stages (see the module docstring)."""

    name = "riann"
    PARAMS = (
        ParamSpec(
            "model_path",
            "",
            "Path of a RIANN-compatible ONNX file; empty = the official weights of the riann package.",
        ),
        ParamSpec(
            "rate_adaptation",
            True,
            "Run the network on its own constant-rate grid (2-5.5 ms) resampled causally from the input, "
            "whatever its rate, jitter or dropouts. Off: every sample goes straight into the network.",
        ),
        ParamSpec("input_model", "auto", "What an input sample is when the grid resamples it: 'points' (the "
                  "signal at the stamp), 'means' (the mean since the previous sample), 'auto' (means when the "
                  "stamps jitter and the gyro says so, else points).", choices=("auto", "points", "means")),
        ParamSpec("sample_delay", SAMPLE_DELAY, "Input steps: with input_model 'auto', a regular stream the grid "
                  "up-samples (slower than ~180 Hz) is read as the signal this long before each stamp: 0 = point "
                  "samples at the stamp, 0.5 = interval means stamped at the end or a MEMS low-pass of half a step's "
                  "group delay; the default halves the worst timing error of either.", min=0.0, max=1.0),
        ParamSpec("ensemble", MAX_COPIES, "Copies of the network run on virtually rotated IMU frames, their "
                  "inclinations averaged (the paper's training augmentation used at run time); 1 = the single "
                  "network. Compute grows with it.", min=1, max=MAX_COPIES),
        *front_end_params(True, "the network"),
        *MAG_CAL_PARAMS,
        ParamSpec("restart_gap", 0.1,
                  "s; after a stamp step longer than this (and than 4 input steps) a fresh network state takes "
                  "over from the first row after the hole. 0 = never.", min=0.0, max=3600.0),
        ParamSpec("hole_blend", True,
                  "After a hole, start from the gyro bridge and hand the inclination over to the fresh network "
                  "as its error falls below the bridge's (weights from the gyro across the hole and the motion "
                  "since). Off: the fresh network's output at once.", runtime=True),
        ParamSpec("tau_mag", 9.0, "s; time constant of the heading correction toward the magnetometer (9D only; "
                  "the default is VQF's tauMag).", min=0.01, max=1000.0, runtime=True),
        ParamSpec("mag_delay", 0.0, "s; latency of the magnetometer behind the gyro, compensated by rotating the "
                  "field with the gyro; with estimate_mag_delay the starting value of the estimate (9D only).",
                  min=0.0, max=0.5, runtime=True),
        ParamSpec("estimate_mag_delay", True, "Estimate the magnetometer's latency online from the field's "
                  "rotation against the gyro's during motion (no reference needed) and compensate it (9D only).",
                  runtime=True),
        ParamSpec("mag_dist_rejection", True, "Detect magnetic disturbances (field norm and dip against a learned "
                  "reference) and hold the heading with the gyro while disturbed (9D only).", runtime=True),
    )
    USES_MAG = True

    def __init__(self, model: BatchedModel | None = None, **params: Any) -> None:
        """``model``: an already loaded model to share (its ``copies`` must equal ``ensemble``); else loaded from
        ``model_path``. The stages are built at the first :meth:`reset` (the base class's constructor calls it)."""
        copies = int(params.get("ensemble", MAX_COPIES))
        if model is not None and model.copies != copies:
            raise ValueError(f"the model runs {model.copies} copies, ensemble is {copies}")
        self.model = model or BatchedModel(params.get("model_path") or None, copies=copies)
        self.stages: list[Stage[Any, Any]] = []
        super().__init__(**params)

    # -- the chain --------------------------------------------------------------------------------
    def _build(self) -> None:
        """The stages, each in its RESET state (its constructor restarts it so)."""
        p = self.params
        self.timeline: Timeline | None = None
        self.grid: Grid | DirectRows = DirectRows()
        if p["rate_adaptation"]:
            self.timeline, self.grid = Timeline(p["restart_gap"], p["input_model"], p["sample_delay"]), Grid()
        front: list[Stage[Any, Any]] = [self.grid] if self.timeline is None else [self.timeline, self.grid]
        self.bias = Bias(p["gyro_bias_estimation"], p["bias_clip"], p["bias_sigma_init"],
                         fixed_step=self.timeline is None)
        self.network = Network(self.model)
        self.carry = Carry()
        self.handover = Handover(p["hole_blend"])
        # the stream's front end (take_front_end), else one of its own that estimates the latency only
        mag_front = self.front or MagFrontEnd(FrontEndConfig(calibrate=False, test=False),
                                              latency=self.front_end_latency())
        self.heading = Heading(p["tau_mag"], p["mag_dist_rejection"], mag_front)
        self.uncertainty = Uncertainty()
        self.stages = [*front, self.bias, self.network, self.carry, self.handover, self.heading, self.uncertainty]

    def reset(self) -> None:
        """Every stage anew (what :data:`~.stage.RESTARTS` says for a reset); the stages are built on the first."""
        if self.stages:
            self._restart(Cause.RESET)
        else:
            self._build()
        self.samples = 0  # input samples taken since reset
        self.last = _NONE  # stage 8's record of the last call
        self.records: UncertaintyIn | None = None  # what the stages output in the last call (stage 8's input)

    def on_gap(self) -> None:
        """A stamp gap longer than the gate's ``max_dt``: each stage does what :data:`~.stage.RESTARTS` says for a
        gap (the network starts afresh without a bridge; bias, rate statistics and heading carry on)."""
        self._restart(Cause.GAP)

    def _restart(self, cause: Cause) -> None:
        for stage in self.stages:
            stage.restart(cause)

    def take_front_end(self, front: MagFrontEnd) -> None:
        """The stream's magnetometer front end: the heading stage's from now on."""
        super().take_front_end(front)
        self.heading.use_front_end(front)

    def front_end_latency(self) -> LatencySettings:
        """The magnetometer's latency as stage 7 treats it: ``mag_delay`` the fixed value or the estimate's start,
        estimated with ``estimate_mag_delay``, compensated (the field rotated back over it by the gyro)."""
        p = self.params
        return LatencySettings(float(p["mag_delay"]), bool(p["estimate_mag_delay"]), compensate=True)

    def _on_params_changed(self) -> None:
        p = self.params
        self.heading.configure(p["tau_mag"], p["mag_dist_rejection"])
        self.heading.mag.front.latency_settings = self.front_end_latency()
        self.handover.configure(p["hole_blend"])

    def heading_observed(self) -> bool:
        return self.heading.mag.observed

    def diagnostics(self) -> dict[str, str]:
        out = self.bias.diagnostics()  # first: the entry all the estimators with a front end give
        for stage in self.stages:
            out.update(stage.diagnostics())
        return out

    def heading_state(self) -> Array:
        """Stage 8's heading state of the samples of the last call (its FREE, USED, HELD are the base class's codes)."""
        return self.last.yaw_features[:, 0].copy()

    def sigma(self, fields: np.ndarray) -> Array:
        """Stage 8's σ of the samples of the last call (``fields`` is not needed: the heading stage knows which
        samples its field corrected)."""
        s = self.last.sigma_rad
        if len(s) != len(fields):
            raise ValueError(f"sigma for {len(fields)} samples asked, the last call had {len(s)}")
        return s.copy()

    def _run(self, x: list[Row6], dt: list[float], mag: list[Vec | None] | None) -> Array:
        """A block of samples through the chain."""
        self.samples += len(x)
        s = Samples.of(x, dt, mag)
        g = self._rows(s)
        b = self.bias.run(g)
        n = self.network.run(NetworkIn(g, b))
        c = self.carry.run(CarryIn(g, b, n))
        h = self.handover.run(HandoverIn(s, g, c))
        q = self.heading.run(HeadingIn(s, c, h))
        self.records = UncertaintyIn(s, g, b, n, h, q)
        self.last = self.uncertainty.run(self.records)
        return q.q

    def _rows(self, s: Samples) -> GridBlock:
        """Stages 1 and 2: the network rows of the samples (with ``rate_adaptation`` off, one row per sample)."""
        if isinstance(self.grid, DirectRows):
            return self.grid.run(s)
        assert self.timeline is not None
        return self.grid.run(self.timeline.run(s))

    # -- public API -----------------------------------------------------------------------------
    def update(self, acc: ArrayLike, gyr: ArrayLike, dt: float, mag: ArrayLike | None = None) -> Array:
        a0, a1, a2 = _vec3(acc)
        g0, g1, g2 = _vec3(gyr)
        m = None if mag is None else _vec3(mag)
        if m is not None and not (math.isfinite(m[0]) and math.isfinite(m[1]) and math.isfinite(m[2])):
            m = None
        return self._run([(a0, a1, a2, g0, g1, g2)], [float(dt)], [m])[0]

    def update_batch(self, acc: ArrayLike, gyr: ArrayLike, dt: ArrayLike, mag: ArrayLike | None = None) -> Array:
        acc = np.asarray(acc, dtype=float).reshape(-1, 3)
        gyr = np.asarray(gyr, dtype=float).reshape(-1, 3)
        n = len(acc)
        if n == 0:
            return np.empty((0, 4))
        dts = np.broadcast_to(np.asarray(dt, dtype=float), (n,)).tolist()
        xs: list[Row6] = np.column_stack([acc, gyr]).tolist()
        fields: list[Vec | None] | None = None
        if mag is not None:
            m = np.asarray(mag, dtype=float).reshape(n, 3)
            ok = np.isfinite(m).all(axis=1).tolist()
            fields = [(v[0], v[1], v[2]) if good else None for v, good in zip(m.tolist(), ok, strict=True)]
        return self._run(xs, dts, fields)


_NONE = Uncertainties(np.zeros((0, 2)), np.zeros((0, 4)), np.zeros((0, 4)))  # before the first call


def _vec3(v: ArrayLike) -> Vec:
    """Three floats of a 3-vector given as a list or tuple (a message's fields) or as an array."""
    if isinstance(v, (list, tuple)):
        a, b, c = v
    else:
        a, b, c = np.asarray(v, dtype=float).reshape(3).tolist()
    return float(a), float(b), float(c)
