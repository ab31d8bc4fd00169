"""Offline attitude evaluation, the paper's way (ROS-free core of ``riann-bag-eval``).

* **Scenarios** (paper, section "Performance Evaluation"), built from a recording with
  :func:`make_scenario`:

  - ``restrictive`` — the recording as it is, from its first sample (with its initial rest), with the
    gyroscope turn-on bias removed: the mean gyro over the *initial rest* (the samples before the first
    scored sample, i.e. before BROAD's first ``movement`` sample) is subtracted from the whole sequence.
    A recording whose first sample is already scored has no known rest: nothing is removed.
  - ``partially-restrictive`` — ``restrictive`` plus a constant gyro bias per axis drawn from
    N(0, (0.5 °/s)²); the generator is seeded per sequence from ``seed`` and the sequence name
    (:func:`sequence_seed`), so every estimator, scenario and rate sees the same bias.
  - ``realistic`` — the ``partially-restrictive`` signals (de-biased, plus the same random bias; the
    paper: "the same gyroscope bias as in the partially restrictive scenario") with the initial rest cut
    away: the sequence starts at the first scored sample, in motion.

* **Scoring** — e_α per sample (paper eq. 3, heading ignored), RMSE over the score mask ∩ reference
  present (∩ estimate present: samples the input gate rejected have no estimate and are counted as
  ``n_unestimated``). Heading and total error RMSEs are optional extra columns.
* **Running** — every estimator runs through :class:`riann_ros.stream.EstimatorStream` with the
  recording's rate as ``nominal_rate``: the very code path of the ROS node, so offline scores are node
  scores.
* **Rates** — :func:`resample` (FFT resampling of acc/gyr with ``scipy.signal.resample``, slerp of the
  reference, nearest neighbour for the score mask), applied to the recording *before* the scenario.
* **Memory** — bags at their native rate are evaluated streamed (:func:`evaluate_bag`: chunks of
  ``STREAM_CHUNK`` samples through one stream per scenario × estimator, scores accumulated), so memory
  does not grow with the bag length; resampled runs (``rates``: the FFT needs the whole sequence),
  ``keep_estimates`` and BROAD files load the whole recording (:func:`evaluate_recording`).
"""

from __future__ import annotations

import hashlib
import itertools
import math
import os
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from riann_ros import quaternion as quat
from riann_ros.estimators import REGISTRY, estimator_class
from riann_ros.estimators.base import AttitudeEstimator
from riann_ros.recording import Recording
from riann_ros.stream import EstimatorStream, GateConfig

RESTRICTIVE = "restrictive"
PARTIAL = "partially-restrictive"
REALISTIC = "realistic"
SCENARIOS = (RESTRICTIVE, PARTIAL, REALISTIC)
BIAS_STD_DPS = 0.5  # °/s, paper: N(0, 0.5 °/s) per axis
STAMP_OFFSET_NS = 1_000_000_000  # added when a recording starts at stamp 0 (the gate rejects stamp 0)
BAG_SUFFIXES = (".mcap", ".db3")
SERIES_POINTS = 6000  # points per curve kept for the error-over-time plot
BROAD_SUFFIXES = (".hdf5", ".h5", ".mat")


class EvalError(Exception):
    """A problem with one input (named in the message); other inputs are still evaluated."""


# ---------------------------------------------------------------------------------------------------
# estimator specs
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class EstimatorSpec:
    """An estimator name with parameters and a readable label, e.g. ``madgwick(beta=0.1)``."""

    name: str
    params: tuple[tuple[str, Any], ...] = ()
    label: str = ""

    @property
    def kwargs(self) -> dict[str, Any]:
        return dict(self.params)

    def create(self) -> AttitudeEstimator:
        return estimator_class(self.name)(**self.kwargs)

    def to_dict(self) -> dict[str, Any]:
        return {"label": self.label, "name": self.name, "params": self.kwargs}


def _parse_value(text: str) -> Any:
    low = text.strip().lower()
    if low in ("true", "false"):
        return low == "true"
    try:
        return float(text)
    except ValueError:
        return text


def _fmt_value(v: Any) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def make_label(name: str, params: dict[str, Any]) -> str:
    if not params:
        return name
    return f"{name}(" + ", ".join(f"{k}={_fmt_value(v)}" for k, v in params.items()) + ")"


def parse_estimator(text: str) -> EstimatorSpec:
    """``"madgwick:beta=0.033"`` / ``"mahony:kp=1:ki=0.3"`` / ``"riann"`` → :class:`EstimatorSpec`.

    The name and the parameters are checked against the estimator's ``PARAMS`` (``ValueError``
    otherwise, naming the known estimators or parameters).
    """
    parts = [p.strip() for p in text.strip().split(":")]
    name = parts[0].lower()
    if not name:
        raise ValueError(f"empty estimator name in {text!r}")
    if name not in REGISTRY:
        raise ValueError(f"unknown estimator {name!r}; known: {', '.join(REGISTRY)}")
    cls = estimator_class(name)  # ImportError if the module is missing
    specs = {p.name.lower(): p for p in cls.PARAMS}
    params: dict[str, Any] = {}
    for item in parts[1:]:
        if "=" not in item:
            raise ValueError(f"{text!r}: expected name=value after ':', got {item!r}")
        key, value = (s.strip() for s in item.split("=", 1))
        spec = specs.get(key.lower())
        if spec is None:
            known = ", ".join(p.name for p in cls.PARAMS) or "none"
            raise ValueError(f"{text!r}: unknown parameter {key!r} for {name}; known: {known}")
        v = _parse_value(value)
        if isinstance(spec.default, str):
            v = value
        params[spec.name] = spec.validate(v)
    cls(**params)  # validates the combination (and fails early, not in a worker)
    return EstimatorSpec(name, tuple(params.items()), make_label(name, params))


def parse_estimators(text: str | Sequence[str]) -> list[EstimatorSpec]:
    """Comma-separated specs (or a list of them) → unique-labelled specs."""
    items = text.split(",") if isinstance(text, str) else [s for t in text for s in t.split(",")]
    out: list[EstimatorSpec] = []
    for item in items:
        if item.strip():
            spec = parse_estimator(item)
            if spec.label in {s.label for s in out}:
                raise ValueError(f"estimator {spec.label} given twice")
            out.append(spec)
    if not out:
        raise ValueError("no estimators given")
    return out


def available_estimators() -> list[str]:
    """Registered estimators whose module imports (others are still being written or lack a dependency)."""
    names = []
    for name in REGISTRY:
        try:
            estimator_class(name)
        except Exception:
            continue
        names.append(name)
    return names


def parse_scenarios(text: str) -> list[str]:
    items = [s.strip().lower() for s in text.split(",") if s.strip()]
    if items == ["all"]:
        return list(SCENARIOS)
    aliases = {"partial": PARTIAL, "partially_restrictive": PARTIAL, "partially-restrictive": PARTIAL}
    out = []
    for s in items:
        s = aliases.get(s, s)
        if s not in SCENARIOS:
            raise ValueError(f"unknown scenario {s!r}; known: {', '.join(SCENARIOS)}, all")
        if s not in out:
            out.append(s)
    if not out:
        raise ValueError("no scenarios given")
    return out


# ---------------------------------------------------------------------------------------------------
# scenarios and resampling
# ---------------------------------------------------------------------------------------------------
def sequence_seed(seed: int, name: str) -> int:
    """Deterministic per-sequence seed from the global seed and the sequence name (sha256)."""
    h = hashlib.sha256(f"{int(seed)}:{name}".encode()).digest()
    return int.from_bytes(h[:8], "little")


def random_bias(seed: int, name: str) -> NDArray[np.float64]:
    """The constant gyro bias (rad/s, 3 axes) of the partially-restrictive and realistic scenarios."""
    rng = np.random.default_rng(sequence_seed(seed, name))
    return np.radians(rng.normal(0.0, BIAS_STD_DPS, 3))


def first_scored_index(rec: Recording) -> int:
    """Index of the first scored sample (the motion onset); the initial rest is ``[0, index)``."""
    mask = np.asarray(rec.score_mask, dtype=bool)
    if not mask.any():
        raise EvalError("no scored samples (the score mask is empty)")
    return int(np.argmax(mask))


@dataclass
class ScenarioInfo:
    scenario: str
    start_index: int  # first sample of the scenario sequence in the (resampled) recording
    rest_samples: int  # initial rest length in the recording
    bias_removed_dps: list[float]  # mean gyro over the initial rest (°/s), subtracted
    bias_added_dps: list[float]  # random bias (°/s), added


def make_scenario(rec: Recording, scenario: str, seed: int = 0) -> tuple[Recording, ScenarioInfo]:
    """The recording prepared for ``scenario`` (see the module docstring)."""
    if scenario not in SCENARIOS:
        raise ValueError(f"unknown scenario {scenario!r}")
    i0 = first_scored_index(rec)
    gyr = rec.gyr.copy()
    removed = np.zeros(3)
    if i0 > 0:
        removed = np.mean(rec.gyr[:i0], axis=0)
        gyr -= removed
    added = np.zeros(3)
    if scenario in (PARTIAL, REALISTIC):
        added = random_bias(seed, rec.name)
        gyr += added
    out = Recording(
        stamps_ns=rec.stamps_ns.copy(),
        acc=rec.acc.copy(),
        gyr=gyr,
        quat_ref=None if rec.quat_ref is None else rec.quat_ref.copy(),
        score_mask=rec.score_mask.copy(),
        name=rec.name,
        dataset=rec.dataset,
        source=rec.source,
        frame_id=rec.frame_id,
        meta=dict(rec.meta),
    )
    start = i0 if scenario == REALISTIC else 0
    if start:
        out = out.slice(start)
    if len(out) and out.stamps_ns[0] <= 0:
        out.stamps_ns = out.stamps_ns + (STAMP_OFFSET_NS - int(out.stamps_ns[0]))
    info = ScenarioInfo(
        scenario=scenario,
        start_index=start,
        rest_samples=i0,
        bias_removed_dps=np.degrees(removed).round(6).tolist(),
        bias_added_dps=np.degrees(added).round(6).tolist(),
    )
    return out, info


def resample(rec: Recording, rate: float) -> Recording:
    """The recording at ``rate`` Hz (:func:`riann_ros.resample.resample_recording`, shared with the rest of
    the project): FFT resampling (``scipy.signal.resample``) of acc and gyr over the whole sequence (as in
    the paper), slerp of the reference, nearest neighbour for the score mask."""
    from riann_ros.resample import resample_recording

    if not (rate > 0 and math.isfinite(rate)):
        raise ValueError(f"rate must be positive, got {rate}")
    return resample_recording(rec, rate)


# ---------------------------------------------------------------------------------------------------
# running and scoring
# ---------------------------------------------------------------------------------------------------
def run_estimator(
    estimator: AttitudeEstimator, rec: Recording, gate: GateConfig | None = None
) -> tuple[NDArray[np.float64], NDArray[np.bool_], dict[str, int]]:
    """Run ``estimator`` over ``rec`` through the node's :class:`EstimatorStream` (reset first).

    Returns (quaternions (N, 4) with NaN rows for rejected samples, accepted mask, gate counters).
    """
    estimator.reset()
    rate = rec.rate_hz if len(rec) > 1 and math.isfinite(rec.rate_hz) else 100.0
    stream = EstimatorStream(estimator, gate or GateConfig(nominal_rate=rate))
    q, accepted = stream.process_batch(rec.stamps_ns, rec.acc, rec.gyr)
    counters = {**{f"rejected_{k}": int(v) for k, v in stream.gate.rejected.items()}}
    counters.update({f"reset_{k}": int(v) for k, v in stream.gate.resets.items()})
    return q, accepted, counters


def _rms_deg(e: NDArray) -> float:
    return float(np.degrees(np.sqrt(np.mean(e**2))))


def score(rec: Recording, q_est: NDArray[np.float64], with_heading: bool = False) -> dict[str, Any]:
    """RMSE of e_α (°) over score mask ∩ reference present ∩ estimate present, and sample counts."""
    if rec.quat_ref is None:
        raise EvalError("no reference orientation (nothing to score against)")
    ref_ok = np.isfinite(rec.quat_ref).all(axis=1)
    est_ok = np.isfinite(q_est).all(axis=1)
    base = rec.score_mask & ref_ok
    if not base.any():
        raise EvalError("no scored samples (score mask ∩ reference present is empty)")
    valid = base & est_ok
    out: dict[str, Any] = {
        "n_samples": len(rec),
        "n_scored": int(valid.sum()),
        "n_unestimated": int((base & ~est_ok).sum()),
    }
    if not valid.any():
        raise EvalError("the estimator gave no output on any scored sample")
    qt, qe = rec.quat_ref[valid], q_est[valid]
    e = quat.inclination_error(qt, qe)
    out["rmse_deg"] = _rms_deg(e)
    out["max_err_deg"] = float(np.degrees(e.max()))
    if with_heading:
        out["heading_rmse_deg"] = _rms_deg(quat.heading_error(qt, qe))
        out["total_rmse_deg"] = _rms_deg(quat.total_error(qt, qe))
    return out


def error_series(rec: Recording, q_est: NDArray[np.float64]) -> NDArray[np.float64]:
    """e_α in degrees per sample (NaN where the reference or the estimate is missing)."""
    return np.degrees(quat.inclination_error(rec.quat_ref, q_est))


# ---------------------------------------------------------------------------------------------------
# loading
# ---------------------------------------------------------------------------------------------------
def load_recording(path: str | os.PathLike[str]) -> Recording:
    """A bag (``.mcap``, ``.db3`` or a bag directory) via :mod:`riann_ros.bagio`, or a BROAD trial file
    (``.hdf5`` / ``.mat``). Raises :class:`EvalError` naming the file on any problem."""
    p = Path(path)
    try:
        if p.suffix.lower() in BROAD_SUFFIXES:
            from riann_ros.datasets.broad import read_broad

            rec = read_broad(p)
        else:
            if not p.exists():
                raise EvalError(f"{p}: no such file or directory")
            from riann_ros import bagio

            rec = bagio.read_recording(p)
    except EvalError:
        raise
    except Exception as exc:  # bagio.BagError, OSError, ValueError, …
        raise EvalError(f"{p}: cannot read: {exc}") from exc
    if len(rec) < 2:
        raise EvalError(f"{p}: fewer than 2 IMU samples")
    if rec.quat_ref is None or not np.isfinite(rec.quat_ref).all(axis=1).any():
        raise EvalError(f"{p}: no reference orientation (nothing to score against)")
    if not rec.score_mask.any():
        raise EvalError(f"{p}: no scored samples (score mask is empty)")
    if not (rec.score_mask & np.isfinite(rec.quat_ref).all(axis=1)).any():
        raise EvalError(f"{p}: no scored samples with a reference")
    if not rec.name or rec.name == "sequence":
        rec.name = p.stem if p.is_file() else p.name
    return rec


# ---------------------------------------------------------------------------------------------------
# the evaluation of one input (one worker task)
# ---------------------------------------------------------------------------------------------------
@dataclass
class EvalSettings:
    estimators: list[EstimatorSpec]
    scenarios: list[str] = field(default_factory=lambda: list(SCENARIOS))
    seed: int = 0
    rates: list[float | None] = field(default_factory=lambda: [None])  # None = the recording's own rate
    with_heading: bool = False
    series_for: str | None = None  # sequence name whose error-over-time series is kept ("*" = first)
    series_step: int = 0  # keep every n-th sample of the series (0: about SERIES_POINTS points)
    keep_estimates: bool = False  # return the estimates (for --write-estimates)


@dataclass
class SequenceResult:
    source: str
    name: str = ""
    dataset: str = ""
    error: str | None = None
    rows: list[dict[str, Any]] = field(default_factory=list)
    scenarios: dict[str, Any] = field(default_factory=dict)  # scenario → ScenarioInfo dict
    series: dict[str, Any] | None = None
    estimates: dict[str, Any] | None = None  # label → (stamps_ns, quats) on the restrictive sequence
    seconds: float = 0.0
    cpu_seconds: float = 0.0  # reading + scenarios + runs + scoring, in the worker
    citation: str = ""


_ESTIMATOR_CACHE: dict[EstimatorSpec, AttitudeEstimator] = {}


def _estimator(spec: EstimatorSpec) -> AttitudeEstimator:
    est = _ESTIMATOR_CACHE.get(spec)
    if est is None:
        est = _ESTIMATOR_CACHE[spec] = spec.create()
    return est


#: ``runner(specs, scenario_recording) -> [(quats (N, 4) with NaN rows, counters), ...]`` one per spec
Runner = Callable[[list[EstimatorSpec], Recording], list[tuple[NDArray[np.float64], dict[str, Any]]]]


def offline_runner(specs: list[EstimatorSpec], rec: Recording) -> list[tuple[NDArray[np.float64], dict[str, Any]]]:
    """Run each estimator in-process through the node's EstimatorStream (counters include ``seconds``)."""
    import time

    out = []
    for spec in specs:
        t, c = time.perf_counter(), time.process_time()
        q, _accepted, counters = run_estimator(_estimator(spec), rec)
        counters["seconds"] = time.perf_counter() - t
        counters["cpu_seconds"] = time.process_time() - c
        out.append((q, counters))
    return out


def evaluate_recording(
    rec: Recording, settings: EvalSettings, source: str = "", runner: Runner | None = None
) -> SequenceResult:
    """Every rate × scenario × estimator on one recording (offline unless another ``runner`` is given)."""
    import time

    t0 = time.perf_counter()
    run = runner or offline_runner
    res = SequenceResult(
        source=source or rec.name, name=rec.name, dataset=rec.dataset or "unknown", citation=rec.source
    )
    want_series = settings.series_for is not None and settings.series_for in ("*", rec.name)
    for rate in settings.rates:
        r = rec if rate is None else resample(rec, rate)
        rate_val = round(r.rate_hz, 3)
        for scenario in settings.scenarios:
            srec, info = make_scenario(r, scenario, settings.seed)
            res.scenarios.setdefault(scenario, asdict(info))
            outputs = run(settings.estimators, srec)
            for spec, (q, counters) in zip(settings.estimators, outputs, strict=True):
                counters = dict(counters)
                secs = counters.pop("seconds", float("nan"))
                row: dict[str, Any] = {
                    "sequence": rec.name,
                    "dataset": res.dataset,
                    "source": res.source,
                    "scenario": scenario,
                    "rate": NATIVE if rate is None else float(rate),
                    "rate_hz": rate_val,
                    "resampled": rate is not None,
                    "estimator": spec.label,
                    "estimator_name": spec.name,
                    "mode": "offline" if runner is None else getattr(runner, "mode", "custom"),
                    "seconds": secs,
                }
                row.update(score(srec, q, settings.with_heading))
                row.update(counters)
                res.rows.append(row)
                if want_series and rate is None:
                    if res.series is None:
                        res.series = {"sequence": rec.name, "curves": {}}
                    step = settings.series_step if settings.series_step > 0 else -(-len(srec) // SERIES_POINTS)
                    e = error_series(srec, q)[::step]
                    res.series["curves"].setdefault(scenario, {})[spec.label] = e.astype(np.float32)
                    res.series.setdefault("t", {})[scenario] = srec.t[::step].astype(np.float32)
                    res.series.setdefault("scored", {})[scenario] = srec.score_mask[::step]
                if settings.keep_estimates and rate is None and scenario == settings.scenarios[0]:
                    if res.estimates is None:
                        stamps = rec.stamps_ns[info.start_index : info.start_index + len(srec)]
                        res.estimates = {"scenario": scenario, "stamps": stamps, "quats": {}}
                    res.estimates["quats"][spec.label] = q
    res.seconds = time.perf_counter() - t0
    return res


# ---------------------------------------------------------------------------------------------------
# streamed evaluation of bags (bounded memory)
# ---------------------------------------------------------------------------------------------------
STREAM_CHUNK = 100_000  # samples per bag chunk when a bag is evaluated streamed


def streams_bag(source: str | os.PathLike[str], settings: EvalSettings) -> bool:
    """Whether :func:`evaluate_source` evaluates ``source`` chunk by chunk (:func:`evaluate_bag`).

    Bags at their native rate only: FFT resampling (``--rates``) needs the whole sequence, and
    ``keep_estimates`` (``--write-estimates``) keeps every estimate anyway; those, and BROAD files
    (small), are loaded whole."""
    return (
        Path(source).suffix.lower() not in BROAD_SUFFIXES
        and all(r is None for r in settings.rates)
        and not settings.keep_estimates
    )


def _median_rate(hist: dict[int, int]) -> float:
    """``Recording.rate_hz`` (1 / median step) from a histogram of the stamp steps (ns → count)."""
    n = sum(hist.values())
    if n == 0:
        return float("nan")
    keys = sorted(hist)
    cum = np.cumsum([hist[k] for k in keys])

    def kth(k: int) -> int:  # the k-th smallest step (0-based)
        return keys[int(np.searchsorted(cum, k, side="right"))]

    if n % 2:
        med = float(np.int64(kth(n // 2)) * 1e-9)
    else:
        med = float(np.median(np.array([kth(n // 2 - 1), kth(n // 2)], dtype=np.int64) * 1e-9))
    return 1.0 / med


def _add_steps(hist: dict[int, int], steps: NDArray[np.int64]) -> None:
    if len(steps):
        vals, counts = np.unique(steps, return_counts=True)
        for v, c in zip(vals.tolist(), counts.tolist(), strict=True):
            hist[v] = hist.get(v, 0) + c


@dataclass
class _BagSummary:
    """What a first pass over a bag gives before the estimators run (all of bounded size)."""

    name: str
    dataset: str
    source: str
    n: int
    first_stamp: int
    i0: int  # first scored sample
    stamp_i0: int
    rest_gyr_mean: NDArray[np.float64]  # mean gyro over [0, i0) (zeros when i0 == 0)
    rate_all: float  # Recording.rate_hz of the whole bag
    rate_from_i0: float  # … of the samples from i0 on (the realistic sequence)


def _read_error(p: Path, exc: Exception) -> EvalError:
    return exc if isinstance(exc, EvalError) else EvalError(f"{p}: cannot read: {exc}")


def _summarise_bag(p: Path, chunk: int) -> _BagSummary:
    """The first pass: the checks of :func:`load_recording`, the initial rest's gyro mean, the rates."""
    from riann_ros import bagio

    if not p.exists():
        raise EvalError(f"{p}: no such file or directory")
    n = 0
    first_stamp = stamp_i0 = 0
    last: int | None = None
    i0 = -1
    has_ref = ref_any = scored_any = scored_ref = False
    rest: list[NDArray[np.float64]] = []
    hist_all: dict[int, int] = {}
    hist_i0: dict[int, int] = {}
    meta: tuple[str, str, str] = ("", "", "")
    try:
        for c in bagio.iter_imu_chunks(p, chunk=chunk):
            m = len(c)
            if n == 0:
                first_stamp = int(c.stamps_ns[0])
                meta = (c.name, c.dataset, c.source)
                has_ref = c.quat_ref is not None
            idx = np.arange(n, n + m)  # global index of each sample
            steps = np.diff(c.stamps_ns, prepend=np.int64(last)) if last is not None else np.diff(c.stamps_ns)
            later = idx if last is not None else idx[1:]  # global index of the later sample of each step
            _add_steps(hist_all, steps)
            if i0 < 0 and c.score_mask.any():
                k = int(np.argmax(c.score_mask))
                i0, stamp_i0 = n + k, int(c.stamps_ns[k])
                rest.append(c.gyr[:k].copy())
            elif i0 < 0:
                rest.append(c.gyr.copy())
            if i0 >= 0:
                _add_steps(hist_i0, steps[later > i0])
            scored_any |= bool(c.score_mask.any())
            if has_ref and c.quat_ref is not None:
                ok = np.isfinite(c.quat_ref).all(axis=1)
                ref_any |= bool(ok.any())
                scored_ref |= bool((ok & c.score_mask).any())
            last = int(c.stamps_ns[-1])
            n += m
    except Exception as exc:  # bagio.BagError, OSError, ValueError, …
        raise _read_error(p, exc) from exc
    if n < 2:
        raise EvalError(f"{p}: fewer than 2 IMU samples")
    if not has_ref or not ref_any:
        raise EvalError(f"{p}: no reference orientation (nothing to score against)")
    if not scored_any:
        raise EvalError(f"{p}: no scored samples (score mask is empty)")
    if not scored_ref:
        raise EvalError(f"{p}: no scored samples with a reference")
    name, dataset, source = meta
    if not name or name == "sequence":
        name = p.stem if p.is_file() else p.name
    gyr_rest = np.concatenate(rest) if rest else np.zeros((0, 3))
    return _BagSummary(
        name=name,
        dataset=dataset,
        source=source,
        n=n,
        first_stamp=first_stamp,
        i0=i0,
        stamp_i0=stamp_i0,
        rest_gyr_mean=np.mean(gyr_rest, axis=0) if i0 > 0 else np.zeros(3),
        rate_all=_median_rate(hist_all),
        rate_from_i0=_median_rate(hist_i0),
    )


class _Accumulator:
    """Running sums for :func:`score` over the chunks of one scenario × estimator run."""

    def __init__(self, with_heading: bool) -> None:
        self.with_heading = with_heading
        self.n = self.n_scored = self.n_unest = self.n_base = 0
        self.sq = self.sq_heading = self.sq_total = 0.0
        self.max_e = -math.inf

    def add(self, quat_ref: NDArray[np.float64], mask: NDArray[np.bool_], q: NDArray[np.float64]) -> None:
        ref_ok = np.isfinite(quat_ref).all(axis=1)
        est_ok = np.isfinite(q).all(axis=1)
        base = mask & ref_ok
        valid = base & est_ok
        self.n += len(q)
        self.n_base += int(base.sum())
        self.n_scored += int(valid.sum())
        self.n_unest += int((base & ~est_ok).sum())
        if valid.any():
            qt, qe = quat_ref[valid], q[valid]
            e = quat.inclination_error(qt, qe)
            self.sq += float(np.sum(e**2))
            self.max_e = max(self.max_e, float(e.max()))
            if self.with_heading:
                self.sq_heading += float(np.sum(quat.heading_error(qt, qe) ** 2))
                self.sq_total += float(np.sum(quat.total_error(qt, qe) ** 2))

    def result(self) -> dict[str, Any]:
        """What :func:`score` returns for the whole sequence (same errors, same keys in the same order)."""
        if self.n_base == 0:
            raise EvalError("no scored samples (score mask ∩ reference present is empty)")
        out: dict[str, Any] = {"n_samples": self.n, "n_scored": self.n_scored, "n_unestimated": self.n_unest}
        if self.n_scored == 0:
            raise EvalError("the estimator gave no output on any scored sample")

        def rms(sq: float) -> float:
            return float(np.degrees(np.sqrt(sq / self.n_scored)))

        out["rmse_deg"] = rms(self.sq)
        out["max_err_deg"] = float(np.degrees(self.max_e))
        if self.with_heading:
            out["heading_rmse_deg"] = rms(self.sq_heading)
            out["total_rmse_deg"] = rms(self.sq_total)
        return out


_STREAM_ESTIMATORS: dict[tuple[EstimatorSpec, str], AttitudeEstimator] = {}


def evaluate_bag(source: str | os.PathLike[str], settings: EvalSettings, chunk: int | None = None) -> SequenceResult:
    """:func:`evaluate_recording` of a bag at its native rate, streamed: the same rows, scenario infos and
    plot series, with memory bounded by the chunk size (``STREAM_CHUNK`` samples) instead of the bag length.

    Two passes over the bag: the first (:func:`_summarise_bag`) makes the checks of
    :func:`load_recording`, takes the mean gyro over the initial rest and the rates (1 / median step of
    the whole bag and of the realistic sequence, the ``nominal_rate`` the whole-recording path uses); the
    second runs one :class:`EstimatorStream` per scenario × estimator over each chunk (``process_batch``
    continues its state across calls) and accumulates the scores. Rates in ``settings`` must be native.
    """
    import time

    from riann_ros import bagio

    if any(r is not None for r in settings.rates):
        raise ValueError("evaluate_bag evaluates at the native rate only (resampling needs the whole sequence)")
    t0 = time.perf_counter()
    p = Path(source)
    chunk = chunk or STREAM_CHUNK
    info = _summarise_bag(p, chunk)
    res = SequenceResult(source=str(source), name=info.name, dataset=info.dataset or "unknown", citation=info.source)
    want_series = settings.series_for is not None and settings.series_for in ("*", info.name)
    specs = settings.estimators

    class _Run:  # one scenario
        def __init__(self, scenario: str) -> None:
            self.scenario = scenario
            self.start = info.i0 if scenario == REALISTIC else 0
            self.added = random_bias(settings.seed, info.name) if scenario in (PARTIAL, REALISTIC) else np.zeros(3)
            first = info.stamp_i0 if self.start else info.first_stamp
            self.first = first
            self.shift = STAMP_OFFSET_NS - first if first <= 0 else 0
            self.length = info.n - self.start
            rate = info.rate_from_i0 if self.start else info.rate_all
            rate = rate if self.length > 1 and math.isfinite(rate) else 100.0
            self.streams = []
            for spec in specs:
                est = _STREAM_ESTIMATORS.get((spec, scenario))
                if est is None:
                    est = _STREAM_ESTIMATORS[(spec, scenario)] = spec.create()
                est.reset()
                self.streams.append(EstimatorStream(est, GateConfig(nominal_rate=rate)))
            self.acc = [_Accumulator(settings.with_heading) for _ in specs]
            self.wall = [0.0] * len(specs)
            self.cpu = [0.0] * len(specs)
            self.step = settings.series_step if settings.series_step > 0 else -(-self.length // SERIES_POINTS)
            self.curves: list[list[NDArray]] = [[] for _ in specs]
            self.t: list[NDArray] = []
            self.scored: list[NDArray] = []
            res.scenarios.setdefault(
                scenario,
                asdict(
                    ScenarioInfo(
                        scenario=scenario,
                        start_index=self.start,
                        rest_samples=info.i0,
                        bias_removed_dps=np.degrees(info.rest_gyr_mean).round(6).tolist(),
                        bias_added_dps=np.degrees(self.added).round(6).tolist(),
                    )
                ),
            )

        def feed(self, c: Recording, offset: int) -> None:
            """Chunk ``c`` whose first sample has the global index ``offset``."""
            k = max(0, self.start - offset)
            if k >= len(c):
                return
            stamps = c.stamps_ns[k:] + self.shift if self.shift else c.stamps_ns[k:]
            gyr = c.gyr[k:].copy()
            if info.i0 > 0:
                gyr -= info.rest_gyr_mean
            if self.scenario in (PARTIAL, REALISTIC):
                gyr += self.added
            acc = c.acc[k:]
            ref = c.quat_ref[k:]
            mask = c.score_mask[k:]
            local = offset + k - self.start  # index of this piece's first sample in the scenario sequence
            pick = slice((-local) % self.step, None, self.step) if want_series else None
            for j, stream in enumerate(self.streams):
                t, cpu = time.perf_counter(), time.process_time()
                q, _accepted = stream.process_batch(stamps, acc, gyr)
                self.wall[j] += time.perf_counter() - t
                self.cpu[j] += time.process_time() - cpu
                self.acc[j].add(ref, mask, q)
                if pick is not None:
                    self.curves[j].append(np.degrees(quat.inclination_error(ref[pick], q[pick])).astype(np.float32))
            if pick is not None:
                self.t.append(((stamps[pick] - (self.first + self.shift)) * 1e-9).astype(np.float32))
                self.scored.append(mask[pick])

    runs = [_Run(s) for s in settings.scenarios]
    offset = 0
    chunks = bagio.iter_imu_chunks(p, chunk=chunk)
    while True:
        try:
            c = next(chunks)
        except StopIteration:
            break
        except Exception as exc:  # reading only: an estimator crash is reported as such by evaluate_source
            raise _read_error(p, exc) from exc
        for run in runs:
            run.feed(c, offset)
        offset += len(c)
    rate_val = round(info.rate_all, 3)
    for run in runs:
        for j, spec in enumerate(specs):
            stream = run.streams[j]
            row: dict[str, Any] = {
                "sequence": info.name,
                "dataset": res.dataset,
                "source": res.source,
                "scenario": run.scenario,
                "rate": NATIVE,
                "rate_hz": rate_val,
                "resampled": False,
                "estimator": spec.label,
                "estimator_name": spec.name,
                "mode": "offline",
                "seconds": run.wall[j],
            }
            row.update(run.acc[j].result())
            row.update({f"rejected_{k}": int(v) for k, v in stream.gate.rejected.items()})
            row.update({f"reset_{k}": int(v) for k, v in stream.gate.resets.items()})
            row["cpu_seconds"] = run.cpu[j]
            res.rows.append(row)
            if want_series:
                if res.series is None:
                    res.series = {"sequence": info.name, "curves": {}}
                res.series["curves"].setdefault(run.scenario, {})[spec.label] = np.concatenate(run.curves[j])
                res.series.setdefault("t", {})[run.scenario] = np.concatenate(run.t)
                res.series.setdefault("scored", {})[run.scenario] = np.concatenate(run.scored)
    res.seconds = time.perf_counter() - t0
    return res


def evaluate_source(source: str, settings: EvalSettings) -> SequenceResult:
    """Load and evaluate one input; any problem ends up in ``result.error`` naming the input.

    Bags at their native rate are evaluated streamed (:func:`evaluate_bag`, memory independent of the
    bag length); resampled runs (``rates``), ``keep_estimates`` and BROAD files load the whole recording."""
    import time

    c0 = time.process_time()
    try:
        if streams_bag(source, settings):
            res = evaluate_bag(source, settings)
        else:
            rec = load_recording(source)
            res = evaluate_recording(rec, settings, str(source))
        res.cpu_seconds = time.process_time() - c0
        return res
    except EvalError as exc:
        return SequenceResult(source=str(source), error=str(exc))
    except Exception as exc:  # an estimator crash must not take the other bags down
        return SequenceResult(source=str(source), error=f"{source}: {type(exc).__name__}: {exc}")


def _init_worker() -> None:
    import signal

    # Ctrl-C reaches the whole process group: the parent handles it and stops the workers
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # one core per worker: ONNX Runtime and BLAS would otherwise fight over the cores
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = "1"


def evaluate_sources(
    sources: Sequence[str],
    settings: EvalSettings,
    jobs: int = 1,
    progress: Callable[[int, int, SequenceResult], None] | None = None,
) -> list[SequenceResult]:
    """Evaluate inputs, in ``jobs`` worker processes when > 1; results in input order."""
    results: list[SequenceResult | None] = [None] * len(sources)
    done = 0
    if jobs <= 1 or len(sources) <= 1:
        for i, src in enumerate(sources):
            results[i] = evaluate_source(src, settings)
            done += 1
            if progress:
                progress(done, len(sources), results[i])  # type: ignore[arg-type]
    else:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor, as_completed

        ctx = mp.get_context("spawn" if os.name == "nt" else "forkserver")
        pool = ProcessPoolExecutor(max_workers=jobs, mp_context=ctx, initializer=_init_worker)
        try:
            futures = {pool.submit(evaluate_source, src, settings): i for i, src in enumerate(sources)}
            for fut in as_completed(futures):
                i = futures[fut]
                try:
                    results[i] = fut.result()
                except Exception as exc:  # a worker died
                    results[i] = SequenceResult(source=str(sources[i]), error=f"{sources[i]}: worker failed: {exc}")
                done += 1
                if progress:
                    progress(done, len(sources), results[i])  # type: ignore[arg-type]
        except BaseException:
            # Ctrl-C (or any error here): stop the workers now instead of waiting for their sequences
            procs = list(getattr(pool, "_processes", {}).values())
            pool.shutdown(wait=False, cancel_futures=True)
            for p in procs:
                if p.is_alive():
                    p.terminate()
            for p in procs:
                p.join(5)
            raise
        pool.shutdown(wait=True)
    return [r for r in results if r is not None]


# ---------------------------------------------------------------------------------------------------
# aggregation
# ---------------------------------------------------------------------------------------------------
ALL_DATASETS = "all"
NATIVE = "native"  # rate key of rows at the recording's own rate


def rate_order(rate: str | float) -> tuple[int, float]:
    """Sort key for rate keys: native first, then ascending Hz."""
    return (0, 0.0) if rate == NATIVE else (1, float(rate))


def aggregate(rows: Iterable[dict[str, Any]], metric: str = "rmse_deg") -> list[dict[str, Any]]:
    """Per estimator × scenario × dataset × rate: n, mean, median, max, min of the per-sequence RMSE
    (BROAD's group averaging: RMSE per trial, then the plain mean). With several datasets an ``all`` group
    over every sequence is added."""
    rows = [r for r in rows if metric in r]
    groups: dict[tuple, list[float]] = {}
    datasets = sorted({r["dataset"] for r in rows})
    for r in rows:
        keys = [r["dataset"]] + ([ALL_DATASETS] if len(datasets) > 1 else [])
        for d in keys:
            groups.setdefault((r["estimator"], r["scenario"], d, r.get("rate", NATIVE)), []).append(float(r[metric]))
    order_est = list(dict.fromkeys(r["estimator"] for r in rows))
    order_scn = [s for s in SCENARIOS if any(r["scenario"] == s for r in rows)]
    order_ds = [*datasets, ALL_DATASETS]
    out = []
    for (est, scn, ds, rate), vals in sorted(
        groups.items(),
        key=lambda kv: (
            order_scn.index(kv[0][1]),
            order_ds.index(kv[0][2]),
            rate_order(kv[0][3]),
            order_est.index(kv[0][0]),
        ),
    ):
        v = np.asarray(vals)
        out.append(
            {
                "estimator": est,
                "scenario": scn,
                "dataset": ds,
                "rate": rate,
                "n": len(v),
                "mean": float(v.mean()),
                "median": float(np.median(v)),
                "max": float(v.max()),
                "min": float(v.min()),
            }
        )
    return out


# ---------------------------------------------------------------------------------------------------
# tuning (the paper's "filters optimised on the test dataset")
# ---------------------------------------------------------------------------------------------------
#: default grids per estimator, keyed by lower-case parameter name as they appear in PARAMS
DEFAULT_GRIDS: dict[str, dict[str, list[float]]] = {
    "madgwick": {"beta": [0.005, 0.01, 0.02, 0.033, 0.05, 0.075, 0.1, 0.15, 0.2, 0.3]},
    "mahony": {"kp": [0.1, 0.2, 0.5, 1.0, 2.0, 5.0], "ki": [0.0, 0.01, 0.03, 0.1, 0.3]},
    "vqf": {"tau_acc": [0.5, 1.0, 2.0, 3.0, 5.0, 8.0, 12.0]},
}


def parse_grid(text: str) -> tuple[str, dict[str, list[float]]]:
    """``"madgwick"`` (default grid) or ``"mahony:kp=0.5/1/2:ki=0/0.3"`` → (name, {param: values})."""
    parts = [p.strip() for p in text.split(":") if p.strip()]
    name = parts[0].lower() if parts else ""
    if name not in REGISTRY:
        raise ValueError(f"unknown estimator {name!r} to tune; known: {', '.join(REGISTRY)}")
    cls = estimator_class(name)
    specs = {p.name.lower(): p for p in cls.PARAMS}
    grid: dict[str, list[float]] = {}
    if len(parts) == 1:
        for key, values in DEFAULT_GRIDS.get(name, {}).items():
            if key in specs:
                grid[specs[key].name] = list(values)
        if not grid:
            raise ValueError(f"no default tuning grid for {name}; give one, e.g. {name}:param=1/2/3")
    for item in parts[1:]:
        if "=" not in item:
            raise ValueError(f"{text!r}: expected param=v1/v2/..., got {item!r}")
        key, values = item.split("=", 1)
        spec = specs.get(key.strip().lower())
        if spec is None:
            raise ValueError(f"{text!r}: unknown parameter {key!r} for {name}; known: {', '.join(specs)}")
        grid[spec.name] = [float(spec.validate(float(v))) for v in values.split("/") if v.strip()]
    return name, grid


def grid_specs(name: str, grid: dict[str, list[float]]) -> list[EstimatorSpec]:
    keys = list(grid)
    out = []
    for combo in itertools.product(*(grid[k] for k in keys)):
        params = dict(zip(keys, combo, strict=True))
        out.append(EstimatorSpec(name, tuple(params.items()), make_label(name, params)))
    return out


def best_of(rows: Iterable[dict[str, Any]], specs: list[EstimatorSpec], scenario: str) -> dict[str, Any]:
    """The spec with the lowest mean RMSE over the sequences in ``scenario`` (all rates pooled)."""
    by_label: dict[str, list[float]] = {}
    for r in rows:
        if r["scenario"] == scenario:
            by_label.setdefault(r["estimator"], []).append(r["rmse_deg"])
    table = []
    for s in specs:
        v = by_label.get(s.label)
        if v:
            table.append({"label": s.label, "params": s.kwargs, "mean": float(np.mean(v)), "max": float(np.max(v))})
    if not table:
        raise EvalError("tuning produced no scores")
    table.sort(key=lambda d: d["mean"])
    return {"scenario": scenario, "best": table[0], "grid": table}
