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


def evaluate_source(source: str, settings: EvalSettings) -> SequenceResult:
    """Load and evaluate one input; any problem ends up in ``result.error`` naming the input."""
    import time

    c0 = time.process_time()
    try:
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
