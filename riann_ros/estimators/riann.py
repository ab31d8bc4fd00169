"""RIANN: the published recurrent network (2 GRU layers × 200 units) run with ONNX Runtime.

Model I/O (the official ``riann.onnx`` of the ``riann`` package, Apache-2.0):
``input`` float32 [1, T, 7] = acc xyz (m/s²), gyr xyz (rad/s), dt (s); ``h0`` [2, 1, 1, 200];
outputs ``output`` [1, T, 4] (unit quaternion w, x, y, z) and ``hn``.

The network was trained on sequences of *constant* time step inside 2–20 ms. Real streams jitter,
drop messages and run at 25 Hz or 1 kHz, so by default (``rate_adaptation``) the estimator puts four
stages around it, each causal, with one output per input sample at that sample's stamp:

1. **Gyro-bias front end** (``gyro_bias_estimation``, :mod:`~riann_ros.estimators.bias`): VQF's bias
   estimator runs on the network's input rows; the bias known before a row is subtracted from its
   gyro, and from the gyro used in stages 3 and 4.
2. **Constant-rate grid** (:mod:`~riann_ros.estimators.grid`): the network runs at a constant step
   ``T`` chosen from a running median of the input steps with hysteresis (2–5.5 ms: the samples go
   straight in; slower inputs are up-sampled to ≤ 5.5 ms, faster ones averaged in blocks of ~5 ms);
   each grid value is resampled causally from the samples up to that stamp (point samples: up-sampled
   along the parabola through the newest three, which keeps the curvature of fast motion at 25–100 Hz;
   irregular streams as interval means or point samples, whichever lets the gyro pass through its samples
   smoothly, ``input_model``; irregular sample times keep their grid step). Stamps that are a regular sample
   clock plus delivery delays (a driver stamping on arrival, or reading a FIFO in bursts: the time
   spanned by 16 steps does not grow like a random walk) are replaced by a de-jittered timeline at the
   clock's mean period.
3. **Carry-forward**: a sample's attitude is the latest network output (at a grid point at or before
   the sample) rotated on by the bias-corrected gyro integral up to the sample's stamp. No latency
   is added; the network's own correction lags by less than one grid step ``T``.
4. **Heading**: RIANN estimates inclination (roll, pitch) only; its yaw is not meaningful. The
   output takes the network's inclination and a heading that starts at zero and follows the
   bias-corrected gyro (each output is the gyro prediction from the previous output, corrected by
   the smallest rotation — about a horizontal axis — that gives it the network's gravity direction).
   With a magnetometer the heading is also pulled toward the tilt-compensated field, with disturbance
   rejection (:mod:`~riann_ros.estimators.heading`); that correction is about the vertical only, so
   the inclination is the same with and without a field.

**Holes.** A stamp step longer than ``restart_gap`` (and than four input steps) while the network
runs means that rotation during the hole is unknown. The grid bridges the hole by interpolation, and
a second network starts after it from a fresh state; after ``restart_warmup`` (default 0: at once)
its state replaces the old one, which would otherwise take several seconds to shed the error the hole
left. Steps longer than the stream's ``max_dt`` (the input gate's ``gap``) start a fresh network
without the bridge (:meth:`RiannEstimator.on_gap`); the bias estimate, the rate estimate and the
heading carry on across both (with a field, the heading re-acquires it: :meth:`MagHeading.reacquire`).
A clock jump, a fault or ``~/reset`` reset everything.

**Ensemble.** The network itself runs as ``ensemble`` copies (default 4), each fed the IMU in a virtually
rotated sensor frame, their gravity directions mapped back and averaged (:mod:`.ensemble`): the paper
trained RIANN with such rotations, and the copies' errors are partly independent. Every stage above sees
the combined network attitude; ``ensemble=1`` is the single network.

``rate_adaptation=false`` is the direct path: every sample is one network row with its own dt
(stages 1 and 4 still apply).

``update`` and ``update_batch`` share the planning code; the batch call runs the network once over
all planned rows, so both give the same numbers (within float32 round-off).
"""

from __future__ import annotations

import importlib.resources
import math
from pathlib import Path
from typing import Any

import numpy as np
import onnxruntime as ort
from numpy.typing import ArrayLike

from riann_ros import quaternion as quat
from riann_ros.estimators.base import Array, AttitudeEstimator, ParamSpec
from riann_ros.estimators.bias import GyroBiasFrontEnd, front_end_params
from riann_ros.estimators.common import BIAS_KEY, bias_text
from riann_ros.estimators.ensemble import FLOAT_ROWS, MAX_COPIES, combine, frames, rotate_rows
from riann_ros.estimators.grid import DT_MIN, REL_EPS, RateTracker, SignalHistory
from riann_ros.estimators.heading import MagHeading
from riann_ros.estimators.heading import from_rotvec as _rotvec
from riann_ros.estimators.heading import qmul as _qmul
from riann_ros.estimators.holes import HoleBlend, bridge_sigma

HIDDEN_SHAPE = (2, 1, 1, 200)
BATCH_CHUNK = 200_000  # network rows per ONNX Runtime call in batch mode
DEFAULT_DT = 0.01  # s, first step when the stream gives none
TIME_EPS_NS = 1000.0  # a grid point this close after the newest stamp counts as reached (1 µs)
RESTART_WARMUP = 0.0  # s a fresh network runs beside the old one after a hole before it takes over
HOLE_STEPS = 4.0  # a hole is also longer than this many median input steps
CLOCK_GAIN = 1.0 / 256.0  # per sample: how fast the de-jittered timeline of a clocked stream follows its stamps
CLOCK_LOST_SIGMAS = 3.0  # a stamp this many delay deviations (+ half a period) late means lost samples before it

Quat = tuple[float, float, float, float]
Row = tuple[float, ...]
IDENTITY_T: Quat = (1.0, 0.0, 0.0, 0.0)
FORK: Row = (1.0,)  # row marker: a fresh network starts beside the running one
JOIN: Row = (2.0,)  # row marker: the fresh network's state replaces the running one


def _twist(q: Quat) -> float:
    """Angle (rad, in (-π, π]) of the rotation about world z in the swing-twist split of ``q``."""
    a = 2.0 * math.atan2(q[3], q[0])
    return math.remainder(a, 2.0 * math.pi)


def default_model_path() -> Path:
    """The official weights shipped in the ``riann`` package."""
    return Path(str(importlib.resources.files("riann") / "riann.onnx"))


def make_session(model_path: str | Path | None = None, threads: int = 1) -> ort.InferenceSession:
    """An ONNX Runtime CPU session for the RIANN model (checks its inputs and outputs)."""
    path = Path(model_path) if model_path else default_model_path()
    if not path.is_file():
        raise FileNotFoundError(f"RIANN model not found: {path}")
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = threads
    opts.inter_op_num_threads = 1
    opts.log_severity_level = 3
    session = ort.InferenceSession(str(path), sess_options=opts, providers=["CPUExecutionProvider"])
    names_in = {i.name for i in session.get_inputs()}
    names_out = {o.name for o in session.get_outputs()}
    if not {"input", "h0"} <= names_in or not {"output", "hn"} <= names_out:
        raise ValueError(
            f"{path} is not a RIANN-compatible model: inputs {sorted(names_in)}, outputs {sorted(names_out)}"
        )
    return session


class _Plan:
    """What the planning of a run of samples produced: network rows and, per sample, the row its
    output is based on (-1: an earlier one), the carry-forward rotation and the gyro increment."""

    def __init__(self) -> None:
        self.rows: list[Row] = []
        self.idx: list[int] = []
        self.rot: list[Quat] = []
        self.delta: list[Quat] = []
        self.holes: list[int] = []  # samples that end a hole (the heading re-acquires the field there)
        self.bridges: list[tuple[float, float]] = []  # per hole: the bridge's uncertainty (deg), the faster rate

    def add(self, idx: int, rot: Quat, delta: Quat) -> None:
        self.idx.append(idx)
        self.rot.append(rot)
        self.delta.append(delta)


class RiannEstimator(AttitudeEstimator):
    """RIANN with its GRU hidden state carried between calls (see the module docstring)."""

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
        ParamSpec("ensemble", MAX_COPIES, "Copies of the network run on virtually rotated IMU frames, their "
                  "inclinations averaged (the paper's training augmentation used at run time); 1 = the single "
                  "network. Compute grows with it.", min=1, max=MAX_COPIES),
        *front_end_params(True, "the network"),
        ParamSpec("restart_gap", 0.1,
                  "s; after a stamp step longer than this (and than 4 input steps) a fresh network takes "
                  "over after restart_warmup. 0 = never.", min=0.0, max=3600.0),
        ParamSpec("hole_blend", True,
                  "After a hole, start from the gyro bridge and hand the inclination over to the fresh network "
                  "as its error falls below the bridge's (weights from the gyro across the hole and the motion "
                  "since). Off: the fresh network's output at once.", runtime=True),
        ParamSpec("restart_warmup", RESTART_WARMUP,
                  "s; how long the fresh network runs beside the old one after a hole before it takes over.",
                  min=0.0, max=60.0),
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

    def __init__(self, session: ort.InferenceSession | None = None, **params: Any) -> None:
        self._session = session or make_session(params.get("model_path") or None)
        super().__init__(**params)

    # -- state ----------------------------------------------------------------------------------
    def reset(self) -> None:
        self._rate: RateTracker | None = None
        self._bias: GyroBiasFrontEnd | None = None
        self._psi = 0.0  # heading offset of the output (rad)
        self._qc_prev: Quat | None = None  # previous carried network attitude (heading stage)
        self.holes = 0
        self.samples = 0  # input samples taken since reset
        self.rows = 0  # network steps run since reset (compute per sample = rows / samples)
        p = self.params
        self._heading = MagHeading(p["tau_mag"], p["mag_delay"], p["mag_dist_rejection"], p["estimate_mag_delay"])
        self.restart()
        self._qc_prev = None

    def _on_params_changed(self) -> None:
        h, p = self._heading, self.params
        h.tau_mag, h.mag_delay, h.reject, h.estimate_delay = (p["tau_mag"], p["mag_delay"], p["mag_dist_rejection"],
                                                              p["estimate_mag_delay"])

    def heading_observed(self) -> bool:
        return self._heading.observed

    def on_gap(self) -> None:
        """A stamp gap longer than the gate's ``max_dt``: the sensor is the same, so its bias, rate and
        the heading carry on (re-acquiring the field, if any); the network starts afresh (no bridge over such
        a gap)."""
        self.restart()
        self._heading.reacquire()

    def restart(self) -> None:
        """Start the network afresh at the next sample; keep the bias and rate estimates and the heading."""
        self._rots = frames(int(self.params["ensemble"]))
        self._h = self._fresh_state()
        self._h_cand: np.ndarray | None = None  # the fresh network after a hole
        self._warm = 0  # rows the fresh network still runs before it takes over
        self._q_net: Quat | None = None  # last network output
        self._hist = SignalHistory()
        self._t = 0.0  # ns of the newest sample, relative to the first one after (re)start
        self._raw = 0.0  # ns: the newest stamp on the same scale (self._t differs from it for a clocked stream)
        self._anchor = 0.0  # ns; grid point m is at anchor + m * T
        self._m = 0
        self._t_net = 0.0  # ns of the last grid point run
        self._started = False
        self._fork_pending = False
        self._blend: HoleBlend | None = None  # the hand-over from the bridge after a hole
        if self._rate is not None:
            self._rate.model_test.clear_window()  # the stamps start again from 0

    def diagnostics(self) -> dict[str, str]:
        out: dict[str, str] = {}
        if self._bias is not None:
            out[BIAS_KEY] = bias_text(self._bias.bias)
        if self._rate is not None and self.params["rate_adaptation"]:
            out["network rate (Hz)"] = f"{1.0 / self._rate.step:.1f}"
            model = "interval means" if self._rate.means else "point samples"
            out["input model"] = model if self._rate.forced is None else model + " (set)"
            out["input stamps"] = "regular clock + delivery jitter" if self._rate.clocked else "sample times"
        out["network copies"] = str(len(self._rots))
        out["network restarts after holes"] = str(self.holes)
        if self._heading.started:
            out["magnetic disturbance"] = "detected" if self._heading.disturbed else "none"
            kind = "estimated" if self._heading.estimate_delay else "fixed"
            out["magnetometer latency (ms)"] = f"{1e3 * self._heading.delay:.1f} ({kind})"
        return out

    def _bias_now(self) -> tuple[float, float, float]:
        return self._bias.bias if self._bias is not None else (0.0, 0.0, 0.0)

    # -- planning: which network rows each input sample produces ----------------------------------
    def _start(self, dt: float) -> None:
        """First sample after reset/restart: set up the rate tracker and the bias front end."""
        d = dt if DT_MIN * 0.01 < dt < 10.0 else DEFAULT_DT
        if self._rate is None:
            model = self.params["input_model"]
            self._rate = RateTracker(d, means=None if model == "auto" else model == "means")
        if self._bias is None and self.params["gyro_bias_estimation"]:
            ts = self._rate.step if self.params["rate_adaptation"] else d
            self._bias = GyroBiasFrontEnd(ts, self.params["bias_clip"], self.params["bias_sigma_init"])
        self._started = True

    def _plan_direct(self, x: Row, dt: float, plan: _Plan) -> None:
        """rate_adaptation=false: the sample is one row with its own dt."""
        if not self._started:
            self._start(dt)
        bx, by, bz = self._bias_now()
        gx, gy, gz = x[3] - bx, x[4] - by, x[5] - bz
        plan.rows.append((x[0], x[1], x[2], gx, gy, gz, dt))
        if self._bias is not None:
            self._bias.update(x[0:3], x[3:6], dt)
        plan.add(len(plan.rows) - 1, IDENTITY_T, _rotvec(gx * dt, gy * dt, gz * dt))

    def _plan_grid(self, x: Row, dt: float, plan: _Plan, switched: bool | None = None) -> None:
        """Take one input sample; append the grid rows it completes (see the module docstring).
        ``switched``: the rate tracker already took this step (and this is what it answered)."""
        rows = plan.rows
        rate = self._rate
        t_prev = self._t
        if not self._started:
            self._start(dt)
            rate = self._rate
            assert rate is not None
            self._anchor = -rate.step * 1e9  # the first grid point on the first sample
            self._m = 0
            self._t_net = self._anchor
            self._t = 0.0
            t_prev = 0.0
        else:
            assert rate is not None
            step = float(round(dt * 1e9))
            gap = self.params["restart_gap"]
            if gap > 0.0 and dt > gap and dt > HOLE_STEPS * rate.median:
                self._fork_pending = True
                plan.holes.append(len(plan.idx))
                w0, w1 = self._hist.x[-1][3:6], x[3:6]
                plan.bridges.append((bridge_sigma(w0, w1, dt), max(math.hypot(*w0), math.hypot(*w1))))
            elif rate.push(dt) if switched is None else switched:
                self._anchor = self._t_net
                self._m = 0
                if self._bias is not None:
                    self._bias.set_ts(rate.step)
            self._raw += step
            if rate.clocked and not self._fork_pending:
                step = self._clock_step(rate.mean_step * 1e9)
            self._t += step
        assert rate is not None
        self._hist.append(self._t, x)
        rate.see(self._t, x[3:6], hole=self._fork_pending)
        bias = self._bias_now()
        delta = self._gyro_rotation(t_prev, bias, rate.means)
        last = self._emit_rows(rows, rate)
        if self._fork_pending:
            self._fork_pending = False
            self.holes += 1
            rows.append(FORK)
            self._warm = max(1, math.ceil(self.params["restart_warmup"] / rate.step))
        rot = self._gyro_rotation(self._t_net, bias, rate.means, TIME_EPS_NS)
        self._hist.trim(self._t_net - max(rate.box_width() * 1e9, rate.step * 1e9) - 1.0)
        plan.add(last, rot, delta)

    def _clock_step(self, period: float) -> float:
        """The step (ns) of a clocked stream's sample on the de-jittered timeline: one clock period, plus a
        small pull toward the stamps (so the timeline follows the stamps' long-term rate and drift but not
        their delivery jitter). A stamp later than the delays can explain (``CLOCK_LOST_SIGMAS`` deviations
        and half a period) follows lost messages: the timeline then advances by the whole periods lost too,
        and the rate tracker counts them (else the hole's time is swallowed, and the period stretched)."""
        pred = self._t + period
        dev = self._raw - pred
        rate = self._rate
        assert rate is not None
        lost = 0
        if dev > 0.5 * period + CLOCK_LOST_SIGMAS * rate.delay_spread() * 1e9:
            lost = round(dev / period)
            rate.count_lost(lost)
        base = (1 + lost) * period
        step = base + CLOCK_GAIN * (dev - lost * period)
        return min(max(step, base - 0.5 * period), base + 0.5 * period)

    def _gyro_rotation(self, t0: float, bias: tuple[float, float, float], means: bool, eps: float = 0.0) -> Quat:
        """Rotation by the bias-corrected gyro from ``t0`` (ns) to the newest sample; identity when ``t0``
        is not more than ``eps`` before it. Serves both the heading increment (from the previous sample)
        and the carry-forward (from the last grid point)."""
        if self._t <= t0 + eps:
            return IDENTITY_T
        g = self._hist.mean(t0, self._t, means, 3, 6)
        s = (self._t - t0) * 1e-9
        return _rotvec((g[0] - bias[0]) * s, (g[1] - bias[1]) * s, (g[2] - bias[2]) * s)

    def _emit_rows(self, rows: list[Row], rate: RateTracker) -> int:
        """Append every grid row up to the newest stamp; return the index of the last one (or -1)."""
        last = -1
        T = rate.step
        T_ns = T * 1e9
        w_ns = rate.box_width() * 1e9
        means = rate.means
        curved = not means and T < rate.input_step * (1.0 - REL_EPS)  # up-sampled point samples: their curvature
        hist = self._hist
        fe = self._bias
        while True:
            tau = self._anchor + (self._m + 1) * T_ns
            if tau > self._t + TIME_EPS_NS:
                break
            v = hist.mean(tau - w_ns, tau, means, curved=curved) if w_ns > 0.0 else hist.value(tau, means)
            bx, by, bz = self._bias_now()
            rows.append((v[0], v[1], v[2], v[3] - bx, v[4] - by, v[5] - bz, T))
            if fe is not None:
                fe.update(v[0:3], v[3:6])
            self._m += 1
            self._t_net = tau
            last = len(rows) - 1
            if self._warm > 0:
                self._warm -= 1
                if self._warm == 0:
                    rows.append(JOIN)
        return last

    def _fast_run(self, dt: np.ndarray, i: int) -> int:
        """End of the run of samples from ``i`` that land exactly on the grid (a clean stream at the
        grid step): those can be planned vectorised. ``i`` itself when none."""
        rate = self._rate
        if (rate is None or not self._started or rate.irregular or rate.clocked or self._warm > 0
                or self._h_cand is not None or abs(self._t - self._t_net) > TIME_EPS_NS
                or abs(rate.median / rate.step - 1.0) > REL_EPS):
            return i
        bad = np.abs(dt[i:] / rate.step - 1.0) > REL_EPS
        return i + int(np.argmax(bad)) if bad.any() else len(dt)

    def _plan_fast(self, acc: Array, gyr: Array, dt: Array, plan: _Plan) -> int:
        """Vectorised :meth:`_plan_grid` for samples exactly one grid step apart (rows = samples).

        Stops before a sample at which the rate tracker switches or finds the stream irregular (that
        sample is planned by :meth:`_plan_grid`); returns the number of samples planned."""
        rate = self._rate
        assert rate is not None
        T = rate.step
        stop: tuple[int, bool] | None = None
        for k, d in enumerate(dt.tolist()):
            switched = rate.push(d)
            if switched or rate.irregular or rate.clocked:
                stop = (k, switched)
                break
        n = len(dt) if stop is None else stop[0]
        if n:
            self._plan_run(acc[:n], gyr[:n], dt[:n], plan, T)
        if stop is not None:
            x = (*acc[n].tolist(), *gyr[n].tolist())
            self._plan_grid(x, float(dt[n]), plan, switched=stop[1])
            n += 1
        return n

    def _plan_run(self, acc: Array, gyr: Array, dt: Array, plan: _Plan, T: float) -> None:
        """Plan samples that are grid points (the tracker has taken their steps): one row each."""
        n = len(dt)
        t_ns = self._t + np.cumsum(np.round(dt * 1e9))
        if self._bias is not None:
            bias = self._bias.update_batch(acc, gyr)
        else:
            bias = np.zeros((n, 3))
        g = gyr - bias
        first = len(plan.rows)
        plan.rows.extend(np.column_stack([acc, g, np.full(n, T)]).tolist())
        g_prev = np.vstack([np.asarray(self._hist.x[-1][3:6])[None, :], gyr[:-1]]) - bias
        s = np.diff(np.concatenate([[self._t], t_ns])) * 1e-9
        delta = quat.from_rotvec(0.5 * (g_prev + g) * s[:, None])
        plan.idx.extend(range(first, first + n))
        plan.rot.extend([IDENTITY_T] * n)
        plan.delta.extend(map(tuple, delta.tolist()))
        self._m += n
        self._raw += float(t_ns[-1]) - self._t  # whole ns: exact in float64, as the per-sample sum
        self._t = float(t_ns[-1])
        self._t_net = self._anchor + self._m * T * 1e9
        hist = self._hist
        test = self._rate.model_test if self._rate is not None else None
        for k in range(max(0, n - 6), n):  # the model test's window: 6 stamps
            x = (*acc[k].tolist(), *gyr[k].tolist())
            if k >= n - 3:
                hist.append(float(t_ns[k]), x)
            if test is not None:
                test.push(float(t_ns[k]), x[3:6], False)  # regular steps: nothing to judge, only the window
        hist.trim(self._t_net - T * 1e9 - 1.0)

    # -- network --------------------------------------------------------------------------------
    def _fresh_state(self) -> np.ndarray:
        """A zero hidden state per copy of the ensemble."""
        return np.zeros((len(self._rots), *HIDDEN_SHAPE), dtype=np.float32)

    def _net(self, rows: list[Row] | np.ndarray, h: np.ndarray) -> tuple[Array, np.ndarray]:
        """Rows through every copy of the ensemble (:mod:`.ensemble`): the combined attitudes, next states."""
        x = np.asarray(rows, dtype=np.float64).reshape(-1, 7)
        hn = np.empty_like(h)
        outs = []
        for m, r in enumerate(self._rots):
            xm = x if m == 0 else rotate_rows(x, r)
            out, hn[m] = self._session.run(["output", "hn"], {"input": xm.astype(np.float32)[None], "h0": h[m]})
            outs.append(out[0].astype(np.float64))
        if len(outs) == 1 or len(x) > FLOAT_ROWS:
            outs = [q / np.linalg.norm(q, axis=-1, keepdims=True) for q in outs]
        return combine(outs, self._rots), hn

    def _run_rows(self, rows: list[Row]) -> Array:
        """Run the planned rows through the network(s); (M, 4) outputs, NaN at markers."""
        out = np.full((len(rows), 4), np.nan)
        marks = [k for k, r in enumerate(rows) if len(r) == 1]
        self.rows += len(rows) - len(marks)
        start = 0
        for end in [*marks, len(rows)]:
            for c in range(start, end, BATCH_CHUNK):
                part = rows[c : min(c + BATCH_CHUNK, end)]
                out[c : c + len(part)], self._h = self._net(part, self._h)
                if self._h_cand is not None:
                    _, self._h_cand = self._net(part, self._h_cand)
            if end < len(rows):
                if rows[end] == FORK:
                    self._h_cand = self._fresh_state()
                elif self._h_cand is not None:
                    self._h, self._h_cand = self._h_cand, None
            start = end + 1
        return out

    # -- output: carry-forward and heading ------------------------------------------------------------
    def _compose(self, net: Array, plan: _Plan, dt: Array, acc: Array, mag: Array | None) -> Array:
        """Per-sample outputs from the network rows and the plan (vectorised heading stage up to the first
        field, then per sample with the magnetic correction)."""
        n = len(plan.idx)
        idx = np.asarray(plan.idx, dtype=np.int64)
        base = np.empty((n, 4))
        has = idx >= 0
        base[has] = net[idx[has]]
        if (~has).any():
            # forward-fill from the last sample with a row of its own (or the previous call's output)
            pos = np.where(has, np.arange(n), -1)
            pos = np.maximum.accumulate(pos)
            if (pos < 0).any():
                if self._q_net is None:
                    raise RuntimeError("no network output yet")
                base[pos < 0] = self._q_net
            base[pos >= 0] = base[pos[pos >= 0]]
        if has.any():
            self._q_net = tuple(base[np.flatnonzero(has)[-1]].tolist())
        qc = quat.normalize(quat.multiply(base, np.asarray(plan.rot)))
        tilt_sd = self._blend_rows(qc, plan, dt, acc)
        prev = np.vstack([np.asarray(self._qc_prev or qc[0])[None, :], qc[:-1]])
        e = quat.multiply(quat.multiply(prev, np.asarray(plan.delta)), quat.conjugate(qc))
        tw = np.remainder(2.0 * np.arctan2(e[:, 3], e[:, 0]) + np.pi, 2.0 * np.pi) - np.pi
        if self._qc_prev is None:
            tw[0] = -2.0 * math.atan2(qc[0, 3], qc[0, 0]) - self._psi  # the output starts at zero heading
        first = self._first_heading_row(mag, n)
        psi = self._psi + np.cumsum(tw)
        if first < n:
            if mag is None:  # the heading started in an earlier call: this batch has no field
                mag = np.full((n, 3), np.nan)
            psi[first:] = self._mag_psi(float(psi[first - 1]) if first else self._psi, tw[first:], qc[first:],
                                        plan.delta[first:], dt[first:], mag[first:], tilt_sd[first:],
                                        {h - first: b[0] for h, b in zip(plan.holes, plan.bridges, strict=True)})
        self._psi = math.remainder(float(psi[-1]), 2.0 * math.pi)
        self._qc_prev = tuple(qc[-1].tolist())
        rz = np.column_stack([np.cos(0.5 * psi), np.zeros(n), np.zeros(n), np.sin(0.5 * psi)])
        q = quat.normalize(quat.multiply(rz, qc))
        return np.where(q[:, :1] < 0.0, -q, q)  # sign convention: w >= 0

    def _blend_one(self, qc: Quat, delta: Quat, dt: float, acc: tuple[float, float, float],
                   bridge: tuple[float, float] | None) -> Quat:
        """The network attitude ``qc`` of one sample after the hand-over from the bridge (:mod:`.holes`);
        ``bridge``: the sample ends a hole (uncertainty of its bridge, the faster rate at its ends)."""
        if bridge is not None and self.params["hole_blend"]:
            self._blend = HoleBlend(bridge[0], qc, bridge[1], acc)
            return qc
        if self._blend is None:
            return qc
        q, going = self._blend.step(qc, delta, dt, acc)
        if not going:
            self._blend = None
        return q

    def _blend_rows(self, qc: Array, plan: _Plan, dt: Array, acc: Array) -> Array:
        """:meth:`_blend_one` over the rows of a batch, in place (only where a hand-over runs); returns each row's
        inclination uncertainty (deg; 0 where no hand-over runs)."""
        starts = dict(zip(plan.holes, plan.bridges, strict=True))
        sd = np.zeros(len(qc))
        i = 0 if self._blend is not None else min(starts, default=len(qc))
        while i < len(qc):
            b = starts.get(i)
            if b is None and self._blend is None:
                i = min((h for h in starts if h > i), default=len(qc))
                continue
            q = self._blend_one(tuple(qc[i].tolist()), plan.delta[i], float(dt[i]), tuple(acc[i].tolist()), b)
            qc[i] = q
            if self._blend is not None:
                sd[i] = self._blend.sigma()
            i += 1
        return sd

    def _first_heading_row(self, mag: Array | None, n: int) -> int:
        """The first row that runs the magnetic heading stage: 0 once a field was seen, else the first row with
        a field (n: none)."""
        if self._heading.started:
            return 0
        if mag is None:
            return n
        has = np.isfinite(mag).all(axis=1)
        return int(np.argmax(has)) if has.any() else n

    def _mag_psi(self, psi: float, tw: Array, qc: Array, delta: list[Quat], dt: Array, mag: Array, tilt_sd: Array,
                 holes: dict[int, float]) -> Array:
        """Heading angles of the rows after the first field: gyro increment plus the magnetic correction
        (``tilt_sd``: each row's inclination uncertainty after a hole; ``holes``: rows that end a hole → the
        uncertainty of the bridge over it, deg)."""
        out = np.empty(len(tw))
        step = self._heading.step
        for i, (t, q, m, h, sd) in enumerate(zip(tw.tolist(), qc.tolist(), mag.tolist(), dt.tolist(), tilt_sd.tolist(),
                                                 strict=True)):
            if i in holes:
                self._heading.reacquire(holes[i])
            psi += t
            c, s = math.cos(0.5 * psi), math.sin(0.5 * psi)
            qo = (c * q[0] - s * q[3], c * q[1] - s * q[2], c * q[2] + s * q[1], c * q[3] + s * q[0])
            ok = math.isfinite(m[0]) and math.isfinite(m[1]) and math.isfinite(m[2])
            psi += step(qo, delta[i], h, (m[0], m[1], m[2]) if ok else None, sd)
            out[i] = psi
        return out

    def _compose_one(self, q_net: Quat, rot: Quat, delta: Quat, dt: float, acc: tuple[float, float, float],
                     mag: tuple[float, float, float] | None, bridge: tuple[float, float] | None) -> Array:
        """:meth:`_compose` for one sample in plain floats (the node's hot path)."""
        qc = _qmul(q_net, rot) if rot is not IDENTITY_T else q_net
        n = math.sqrt(sum(v * v for v in qc))
        qc = (qc[0] / n, qc[1] / n, qc[2] / n, qc[3] / n)
        tilt_sd = 0.0
        if bridge is not None or self._blend is not None:
            qc = self._blend_one(qc, delta, dt, acc, bridge)
            if self._blend is not None:
                tilt_sd = self._blend.sigma()
        if self._qc_prev is None:
            self._psi = -2.0 * math.atan2(qc[3], qc[0])
        else:
            p = _qmul(self._qc_prev, delta)
            e = _qmul(p, (qc[0], -qc[1], -qc[2], -qc[3]))
            self._psi = math.remainder(self._psi + _twist(e), 2.0 * math.pi)
        self._qc_prev = qc
        if mag is not None or self._heading.started:
            h = 0.5 * self._psi
            qo = _qmul((math.cos(h), 0.0, 0.0, math.sin(h)), qc)
            self._psi = math.remainder(self._psi + self._heading.step(qo, delta, dt, mag, tilt_sd), 2.0 * math.pi)
        h = 0.5 * self._psi
        w, x, y, z = _qmul((math.cos(h), 0.0, 0.0, math.sin(h)), qc)
        n = math.sqrt(w * w + x * x + y * y + z * z)
        if w < 0.0:  # sign convention: w >= 0
            n = -n
        return np.array([w / n, x / n, y / n, z / n])

    # -- public API -----------------------------------------------------------------------------
    def update(self, acc: ArrayLike, gyr: ArrayLike, dt: float, mag: ArrayLike | None = None) -> Array:
        a0, a1, a2 = acc  # type: ignore[misc, str-unpack]
        g0, g1, g2 = gyr  # type: ignore[misc, str-unpack]
        x = (float(a0), float(a1), float(a2), float(g0), float(g1), float(g2))  # type: ignore[arg-type]
        plan = _Plan()
        self.samples += 1
        if self.params["rate_adaptation"]:
            self._plan_grid(x, float(dt), plan)
        else:
            self._plan_direct(x, float(dt), plan)
        if plan.rows:
            net = self._run_rows(plan.rows)
            if plan.idx[0] >= 0:
                self._q_net = tuple(net[plan.idx[0]].tolist())
        if self._q_net is None:  # cannot happen: the first sample always makes a row
            raise RuntimeError("no network output yet")
        m = None
        if mag is not None:
            m0, m1, m2 = (float(v) for v in mag)  # type: ignore[union-attr, arg-type]
            m = (m0, m1, m2) if math.isfinite(m0) and math.isfinite(m1) and math.isfinite(m2) else None
        if plan.holes:
            self._heading.reacquire(plan.bridges[0][0])
        bridge = plan.bridges[0] if plan.bridges else None
        return self._compose_one(self._q_net, plan.rot[0], plan.delta[0], _step_dt(float(dt)), (x[0], x[1], x[2]), m,
                                 bridge)

    def update_batch(self, acc: ArrayLike, gyr: ArrayLike, dt: ArrayLike, mag: ArrayLike | None = None) -> Array:
        acc = np.asarray(acc, dtype=float).reshape(-1, 3)
        gyr = np.asarray(gyr, dtype=float).reshape(-1, 3)
        n = len(acc)
        dt = np.array(np.broadcast_to(np.asarray(dt, dtype=float), (n,)), dtype=float)
        if n == 0:
            return np.empty((0, 4))
        plan = _Plan()
        self.samples += n
        xs = np.column_stack([acc, gyr]).tolist()
        dts = dt.tolist()
        grid = self.params["rate_adaptation"]
        i = 0
        while i < n:
            j = self._fast_run(dt, i) if grid else i
            if j - i >= 2:
                i += self._plan_fast(acc[i:j], gyr[i:j], dt[i:j], plan)
                continue
            if grid:
                self._plan_grid(tuple(xs[i]), dts[i], plan)
            else:
                self._plan_direct(tuple(xs[i]), dts[i], plan)
            i += 1
        net = self._run_rows(plan.rows) if plan.rows else np.empty((0, 4))
        m = None if mag is None else np.asarray(mag, dtype=float).reshape(n, 3)
        return self._compose(net, plan, np.array([_step_dt(v) for v in dts]), acc, m)


def _step_dt(dt: float) -> float:
    """A sample's dt for the heading stage (non-finite or negative: 0)."""
    return dt if math.isfinite(dt) and dt > 0.0 else 0.0
