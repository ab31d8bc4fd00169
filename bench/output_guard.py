"""Every estimator's output on the BROAD trials, recorded once and compared later: the guard of a change that must
not move one number (a redesign, a faster network call).

Usage::

    .venv/bin/python bench/output_guard.py record DIR [--jobs 2] [--trials 02,07] [--skip-existing]
    .venv/bin/python bench/output_guard.py check DIR [--jobs 2] [--tol 1e-6] [--trials 02,07] [--modes 6d]
        [--condition none --condition bias:3,3,0] [--rates 25]

The code it runs is the riann_ros Python imports: the checkout whose ``.venv`` runs it (``make setup`` installs
that checkout), or another one with ``PYTHONPATH=<checkout>``; the first line it prints names it.

For each BROAD trial (``$RIANN_BROAD_DIR`` or ``../shared/datasets/broad``) and each of 6D (``--use-mag false``)
and 9D (``--use-mag auto``), every estimator (``--estimators``, default RIANN, VQF, Madgwick and Mahony) at its
defaults runs through the evaluator's own pipeline (:func:`riann_ros.evaluation.evaluate_source`, so scenario
cropping, perturbations and the input gate are part of what is guarded) under every condition of
``bench/bench_accuracy.py``: scenarios as-recorded and realistic × its perturbations, and the as-recorded scenario at
its resampled rates; 9D runs the recorded field and the three magnetometer calibration conditions of
``bench/results_tables.py``'s magcal table (hard irons and a soft iron injected, :data:`MAGNETIC`), as recorded and
under the stream's timing faults (:data:`CONDITIONS_9D`). ``record`` writes every output quaternion and its σ
(float32: its round-off, 6e-8, is far below any tolerance used) to ``DIR/<trial>-<6d|9d>.npz``, keyed
``scenario|condition|rate|estimator`` (the σ under ``…|sigma``); ``check`` recomputes them and prints the largest
difference per file (and of its outputs alone) and every run (outputs, or σ, then per column: inclination, heading)
that differs by more than ``--tol``, exiting 1 when one does.
``--condition`` (repeated) and ``--rates`` check (or record) a subset, compared on the runs it holds. The files are
derived from BROAD and stay outside the repository (``test/test_output_guard.py`` reads them from
``$RIANN_OUTPUT_GUARD`` and skips without them).
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import sys
from pathlib import Path
from typing import Any

import numpy as np
from bench_accuracy import CONDITIONS, RATES

import riann_ros
from riann_ros.datasets.broad import broad_files, find_broad_dir

MODES = {"6d": "false", "9d": "auto"}
ESTIMATORS = "riann,vqf,madgwick,mahony"
#: the magnetometer calibration conditions (BENCHMARKS "Magnetometer calibration online"), guarded in 9D
MAGNETIC = ("magnetic:offset:20,0,-10", "magnetic:offset:0,28,-21",
            "magnetic:soft:1.15,0.05,0,0,0.85,0.05,0.05,0,1+magnetic:offset:10,-20,-20")
#: 9D: the recorded field and the calibration conditions, as recorded and with the stream's restarts and timing (a
#: hole, a gap, jitter, stamps on arrival); the resampled rates and the other perturbations are 6D's (the 9D run
#: of every condition costs ten times the 6D one on two cores)
CONDITIONS_9D = ("none", "jitter:10/20/30ms", "latency:0-10ms", "dropout:0.1-0.6s@10s", *MAGNETIC)


def outputs(trial: str, use_mag: str, conditions: tuple[str, ...] = CONDITIONS,
            rates: str = RATES, estimators: str = ESTIMATORS) -> dict[str, np.ndarray]:
    """key ``scenario|condition|rate|estimator`` -> (N, 4) outputs of one trial, in the evaluator's pipeline, and
    ``…|sigma`` -> their σ (rad; N × 2, or 3 with the heading state)."""
    from riann_ros import evaluation as ev
    from riann_ros.evaluation import scenario_run as run_mod
    from riann_ros.evaluation.runners import run_sigmas

    got: dict[str, list[np.ndarray]] = {}
    rate_now: list[str] = ["native"]
    orig = run_mod.ScenarioRun.feed

    def feed(self: Any, chunk: Any, offset: int) -> None:
        inner = self.run

        class Tap:
            def feed(_tap: Any, rec: Any) -> list[np.ndarray]:
                qs = inner.feed(rec)
                key = f"{self.plan.scenario}|{self.condition.label}|{rate_now[0]}"
                sigmas = run_sigmas(inner, len(qs))
                for spec, q, sig in zip(self.own, qs, sigmas, strict=True):
                    got.setdefault(f"{key}|{spec.label}", []).append(np.asarray(q, dtype=np.float32))
                    if sig is not None:
                        got.setdefault(f"{key}|{spec.label}|sigma", []).append(np.asarray(sig, dtype=np.float32))
                return qs

            @property
            def sigmas(_tap: Any) -> Any:
                return getattr(inner, "sigmas", None)

            def finish(_tap: Any) -> Any:
                return inner.finish()

        self.run = Tap()
        try:
            orig(self, chunk, offset)
        finally:
            self.run = inner

    run_mod.ScenarioRun.feed = feed  # type: ignore[method-assign]
    try:
        base = dict(estimators=ev.parse_estimators(estimators), seed=0, use_mag=use_mag)
        perturbed = ev.EvalSettings(scenarios=["as-recorded", "realistic"],
                                    conditions=[ev.parse_condition(c) for c in conditions], **base)
        res = ev.evaluate_source(trial, perturbed)
        if res.error:
            raise RuntimeError(res.error)
        for r in filter(None, rates.split(",")):
            rate_now[0] = r
            res = ev.evaluate_source(trial, ev.EvalSettings(scenarios=["as-recorded"], rates=[float(r)], **base))
            if res.error:
                raise RuntimeError(res.error)
    finally:
        run_mod.ScenarioRun.feed = orig  # type: ignore[method-assign]
    return {k: np.concatenate(v) for k, v in got.items()}


def _file(trial: Path, mode: str) -> str:
    return f"{trial.name[:2]}-{mode}.npz"


def _no_arena() -> None:
    """ONNX Runtime sessions without the CPU memory arena: the evaluator keeps a RIANN estimator per condition alive
    at once, and each arena would keep its largest call's buffers (GBs per worker). The outputs do not depend on it."""
    import onnxruntime as ort

    class Options(ort.SessionOptions):
        def __init__(self) -> None:
            super().__init__()
            self.enable_cpu_mem_arena = False

    ort.SessionOptions = Options  # type: ignore[misc]


def _difference(a: np.ndarray, b: np.ndarray) -> float:
    """The largest absolute difference of two recorded runs (inf: other shapes or NaN at other places)."""
    if a.shape != b.shape or not np.array_equal(np.isnan(a), np.isnan(b)):
        return float("inf")
    d = np.abs(a - b)
    return float(np.nanmax(d)) if np.isfinite(d).any() else 0.0  # (no value, or NaN at the same places only)


def _job(args: tuple[str, str, str, str, str, tuple[str, ...] | None, str | None, float]) -> tuple[str, float, str]:
    import os

    os.environ["OMP_NUM_THREADS"] = "1"
    _no_arena()
    action, trial, mode, out_dir, estimators, conditions, rates, tol = args
    out = outputs(trial, MODES[mode], conditions or (CONDITIONS_9D if mode == "9d" else CONDITIONS),
                  rates if rates is not None else (RATES if mode == "6d" else ""), estimators)
    path = Path(out_dir) / _file(Path(trial), mode)
    if action == "record":
        np.savez_compressed(path, **out)
        return path.name, 0.0, f"{len(out)} runs, {sum(len(v) for v in out.values())} outputs"
    ref = np.load(path)
    subset = conditions is not None or rates is not None
    missing = sorted(set(out) - set(ref.files)) + ([] if subset else sorted(set(ref.files) - set(out)))
    if missing:
        return path.name, float("inf"), f"runs differ: {missing}"
    worst, lines, outs = 0.0, [], 0.0
    for k in sorted(out):
        a, b = ref[k].astype(np.float64), out[k].astype(np.float64)
        d = _difference(a, b)
        worst = max(worst, d)
        if not k.endswith("|sigma"):
            outs = max(outs, d)
        if d > tol:
            lines.append(f"\n    {k}: {d:.3g}{_by_column(a, b) if k.endswith('|sigma') else ''}")
    return path.name, worst, f"over {len(out)} runs (outputs alone: {outs:.3g})" + "".join(lines)


def _by_column(a: np.ndarray, b: np.ndarray) -> str:
    """A σ run's difference per column: the inclination's and the heading's (where the shapes agree)."""
    if a.shape != b.shape or a.ndim != 2:
        return ""
    names = ("inclination", "heading", "heading state")
    return " (" + ", ".join(f"{names[j] if j < len(names) else j}: {_difference(a[:, j], b[:, j]):.3g}"
                            for j in range(a.shape[1])) + ")"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("action", choices=("record", "check"))
    ap.add_argument("dir", type=Path)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--tol", type=float, default=1e-6)
    ap.add_argument("--trials", default="", help="comma-separated trial numbers (default: all)")
    ap.add_argument("--modes", default="6d,9d")
    ap.add_argument("--estimators", default=ESTIMATORS)
    ap.add_argument("--skip-existing", action="store_true", help="record: keep the files already there")
    ap.add_argument("--condition", action="append", default=None,
                    help="a condition to check (repeat it; default: all of the mode's)")
    ap.add_argument("--rates", default=None, help="comma-separated resampled rates (default: 6D's all, 9D none)")
    args = ap.parse_args(argv)
    # the code under test is the riann_ros Python imports: the checkout its .venv installed, or PYTHONPATH=<checkout>
    print(f"{args.action}: riann_ros from {Path(riann_ros.__file__).parent}", file=sys.stderr)
    d = find_broad_dir()
    if d is None:
        print("BROAD not found (set RIANN_BROAD_DIR)", file=sys.stderr)
        return 1
    trials = [p for p in broad_files(d) if not args.trials or p.name[:2] in args.trials.split(",")]
    args.dir.mkdir(parents=True, exist_ok=True)
    conditions = tuple(args.condition) if args.condition else None
    jobs = [(args.action, str(t), m, str(args.dir), args.estimators, conditions, args.rates, args.tol)
            for t in trials for m in args.modes.split(",")
            if not (args.skip_existing and args.action == "record" and (args.dir / _file(t, m)).is_file())]
    # a fresh process per trial: ONNX Runtime's arenas of many sessions would otherwise add up to GBs per worker
    with mp.get_context("forkserver").Pool(args.jobs, maxtasksperchild=1) as pool:
        results = pool.map(_job, jobs, chunksize=1)
    bad = 0
    for name, worst, info in sorted(results):
        flag = "" if worst <= args.tol else "  EXCEEDS"
        bad += worst > args.tol
        print(f"{name}: max |diff| {worst:.3g} {info}{flag}" if args.action == "check" else f"{name}: {info}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
