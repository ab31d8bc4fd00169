"""``riann-bag-eval``: score attitude estimators on dataset bags the paper's way.

Example::

    riann-bag-eval bags/*.mcap --estimators riann,madgwick:beta=0.033,mahony:kp=1:ki=0.3,vqf \\
        --scenarios all --seed 0 --jobs 2 --out eval_out

Inputs are rosbag2 bags in the layout of :mod:`riann_ros.bagio` (``.mcap`` files or bag directories) or
BROAD trial files (``.hdf5`` / ``.mat``). Exit status: 0 all inputs evaluated, 1 some input failed
(named on stderr, the others are still evaluated and reported), 2 bad command line.
"""

from __future__ import annotations

import argparse
import re
import shlex
import sys
import time
from pathlib import Path
from typing import Any

from riann_ros import evaluation as ev
from riann_ros import report

DEFAULT_ESTIMATORS = "riann,madgwick,mahony,vqf"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="riann-bag-eval",
        description="Attitude RMSE (e_α, heading ignored) of RIANN, Madgwick, Mahony and VQF on dataset bags, "
        "in the paper's restrictive / partially-restrictive / realistic scenarios.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="estimator specs: NAME[:PARAM=VALUE[:PARAM=VALUE...]], comma-separated, e.g.\n"
        "  riann,madgwick:beta=0.033,madgwick:beta=0.1,mahony:kp=1:ki=0.3,vqf:tau_acc=3\n"
        "tuning specs: NAME (default grid) or NAME:PARAM=V1/V2/...[:PARAM=...], e.g. mahony:kp=0.5/1/2:ki=0/0.3\n"
        "exit status: 0 ok, 1 some input failed, 2 usage error",
    )
    p.add_argument("inputs", nargs="+", metavar="BAG", help="bags (.mcap, bag directories) or BROAD .hdf5/.mat files")
    p.add_argument(
        "--estimators",
        "-e",
        default=None,
        help=f"estimator specs (default: those of {DEFAULT_ESTIMATORS} that are installed)",
    )
    p.add_argument(
        "--scenarios",
        "-s",
        default="all",
        help="restrictive, partially-restrictive, realistic or all (comma-separated; default all)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the random gyro bias (per sequence: seed + name)")
    p.add_argument(
        "--rates",
        default=None,
        help="comma-separated sampling rates (Hz) to resample to (FFT), e.g. 50,100,200,500; "
        "'native' keeps the recording's own rate",
    )
    p.add_argument("--jobs", "-j", type=int, default=1, help="parallel worker processes (one per sequence)")
    p.add_argument(
        "--out",
        "-o",
        type=Path,
        default=None,
        help="write results.csv, results.json, report.md and plots (PNG+SVG) here",
    )
    p.add_argument("--heading", action="store_true", help="also score heading and total error (extra columns)")
    p.add_argument(
        "--plot-sequence", default=None, help="sequence name for the error-over-time plot (default: the first input)"
    )
    p.add_argument("--no-plots", action="store_true", help="skip the plots")
    p.add_argument(
        "--tune",
        action="append",
        default=[],
        metavar="SPEC",
        help="grid-search this estimator's parameters for the lowest mean RMSE on the inputs and add "
        "the best one to the comparison (repeatable)",
    )
    p.add_argument("--tune-scenario", default=ev.REALISTIC, help="scenario the tuning minimises (default realistic)")
    p.add_argument(
        "--write-estimates",
        type=Path,
        default=None,
        metavar="DIR",
        help="write a copy of every input bag into DIR with each estimator's output as "
        "geometry_msgs/QuaternionStamped topics /eval/<scenario>/<estimator> (first scenario)",
    )
    p.add_argument("--force", action="store_true", help="overwrite existing --write-estimates outputs")
    p.add_argument("--live", action="store_true", help="replay over DDS to the ROS nodes (not implemented yet)")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bar")
    return p


def _parse_rates(text: str | None) -> list[float | None]:
    if not text:
        return [None]
    out: list[float | None] = []
    for item in text.split(","):
        item = item.strip().lower()
        if not item:
            continue
        if item == "native":
            out.append(None)
            continue
        r = float(item)
        if not r > 0:
            raise ValueError(f"rate must be positive, got {item}")
        out.append(r)
    return out or [None]


def topic_for(scenario: str, label: str) -> str:
    """A valid ROS topic name for an estimator's estimates."""
    clean = re.sub(r"[^A-Za-z0-9_]+", "_", label).strip("_")
    return f"/eval/{scenario.replace('-', '_')}/{clean}"


def _err(msg: str) -> None:
    print(f"riann-bag-eval: {msg}", file=sys.stderr)


def _run_tuning(args, sources: list[str], settings: ev.EvalSettings, quiet: bool) -> tuple[list[dict], list]:
    tuning, extra = [], []
    for text in args.tune:
        name, grid = ev.parse_grid(text)
        specs = ev.grid_specs(name, grid)
        tset = ev.EvalSettings(estimators=specs, scenarios=[args.tune_scenario], seed=settings.seed, rates=[None])
        if not quiet:
            print(
                f"tuning {name}: {len(specs)} combinations on {len(sources)} input(s), {args.tune_scenario}",
                file=sys.stderr,
            )
        results = ev.evaluate_sources(sources, tset, args.jobs, report.Progress(len(sources), enabled=not quiet))
        rows = [r for res in results if not res.error for r in res.rows]
        best = ev.best_of(rows, specs, args.tune_scenario)
        best["estimator"] = name
        tuning.append(best)
        b = best["best"]
        label = f"{ev.make_label(name, b['params'])} tuned"
        extra.append(ev.EstimatorSpec(name, tuple(b["params"].items()), label))
        print(
            f"tuned {name} on {args.tune_scenario}: {b['label']} mean {b['mean']:.2f}° max {b['max']:.2f}°",
            file=sys.stderr,
        )
    return tuning, extra


def _write_estimates(results: list[ev.SequenceResult], out_dir: Path, force: bool) -> list[str]:
    from riann_ros import bagio

    problems = []
    out_dir.mkdir(parents=True, exist_ok=True)
    for res in results:
        if res.error or not res.estimates:
            continue
        src = Path(res.source)
        if src.suffix.lower() in ev.BROAD_SUFFIXES:
            problems.append(f"{src}: --write-estimates needs a bag input, not a dataset file")
            continue
        est = res.estimates
        topics = {topic_for(est["scenario"], lbl): (est["stamps"], q) for lbl, q in est["quats"].items()}
        dst = out_dir / src.name
        try:
            bagio.write_estimates(src, dst, topics, force=force)
            print(f"wrote {dst} ({', '.join(topics)})", file=sys.stderr)
        except Exception as exc:
            problems.append(f"{src}: cannot write estimates to {dst}: {exc}")
    return problems


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    argv_list = sys.argv[1:] if argv is None else list(argv)
    if args.live:
        _err(
            "--live is not implemented yet; run without it for the offline evaluation (the same code path "
            "as the nodes: riann_ros.stream.EstimatorStream)"
        )
        return 2
    try:
        spec_text = args.estimators or ",".join(
            n for n in DEFAULT_ESTIMATORS.split(",") if n in ev.available_estimators()
        )
        estimators = ev.parse_estimators(spec_text)
        scenarios = ev.parse_scenarios(args.scenarios)
        rates = _parse_rates(args.rates)
        if args.tune_scenario not in ev.SCENARIOS:
            raise ValueError(f"unknown --tune-scenario {args.tune_scenario!r}; known: {', '.join(ev.SCENARIOS)}")
        for t in args.tune:
            ev.parse_grid(t)
        if args.jobs < 1:
            raise ValueError("--jobs must be at least 1")
    except (ValueError, ImportError) as exc:
        _err(str(exc))
        return 2
    sources = [str(s) for s in args.inputs]
    quiet = args.quiet
    t_start = time.perf_counter()
    settings = ev.EvalSettings(
        estimators=estimators,
        scenarios=scenarios,
        seed=args.seed,
        rates=rates,
        with_heading=args.heading,
        series_for=None if args.no_plots or not args.out else (args.plot_sequence or "*"),
        keep_estimates=args.write_estimates is not None,
    )
    tuning: list[dict[str, Any]] = []
    if args.tune:
        try:
            tuning, extra = _run_tuning(args, sources, settings, quiet)
        except ev.EvalError as exc:
            _err(f"tuning failed: {exc}")
            return 1
        settings.estimators = [
            *settings.estimators,
            *(s for s in extra if s.label not in {e.label for e in estimators}),
        ]

    results = ev.evaluate_sources(sources, settings, args.jobs, report.Progress(len(sources), enabled=not quiet))
    if settings.series_for and settings.series_for != "*" and not any(r.series for r in results):
        _err(f"--plot-sequence {settings.series_for!r} matches no evaluated sequence")
    elapsed = time.perf_counter() - t_start
    failures = [{"source": r.source, "error": r.error} for r in results if r.error]
    for f in failures:
        _err(f"FAILED {f['error']}")
    rows = [row for r in results if not r.error for row in r.rows]
    agg = ev.aggregate(rows)
    print(report.format_table(agg))
    print(
        f"\n{len(results) - len(failures)} of {len(results)} input(s) evaluated in {elapsed:.1f} s"
        + (f"; {len(failures)} failed" if failures else "")
    )

    problems: list[str] = []
    if args.write_estimates is not None:
        problems = _write_estimates(results, args.write_estimates, args.force)
        for p in problems:
            _err(p)

    if args.out:
        out = args.out
        out.mkdir(parents=True, exist_ok=True)
        settings_dict = {
            "command": "riann-bag-eval " + shlex.join(argv_list),
            "inputs": sources,
            "estimators": [e.to_dict() for e in settings.estimators],
            "scenarios": scenarios,
            "seed": args.seed,
            "rates": rates,
            "jobs": args.jobs,
            "bias_std_dps": ev.BIAS_STD_DPS,
            "scenario_definition": {
                ev.RESTRICTIVE: "from the first sample; mean gyro over the initial rest (samples before the first "
                "scored sample) subtracted",
                ev.PARTIAL: "restrictive + constant gyro bias per axis ~ N(0, 0.5 deg/s), seeded per sequence "
                "(sha256 of '<seed>:<sequence name>')",
                ev.REALISTIC: "partially-restrictive signals (same bias) starting at the first scored sample",
            },
            "metric": "RMSE of e_alpha = 2 acos(sqrt(w^2+z^2)) of q_ref * conj(q_est), deg, over score mask & "
            "reference present & estimate present",
        }
        payload = {
            "settings": settings_dict,
            "versions": report.versions(),
            "elapsed_s": elapsed,
            "summary": agg,
            "sequences": [
                {
                    "source": r.source,
                    "name": r.name,
                    "dataset": r.dataset,
                    "seconds": r.seconds,
                    "scenarios": r.scenarios,
                }
                for r in results
                if not r.error
            ],
            "results": rows,
            "tuning": tuning,
            "failures": failures,
        }
        report.write_csv(out / "results.csv", rows)
        report.write_json(out / "results.json", payload)
        plots: list[Path] = []
        if not args.no_plots and rows:
            plots += report.plot_boxes(rows, out)
            series = next((r.series for r in results if r.series), None)
            if series:
                plots += report.plot_error_over_time(series, out)
            plots += report.plot_rmse_vs_rate(rows, out)
        sources_text = sorted({r.citation for r in results if r.citation and not r.error})
        report.write_markdown(out / "report.md", agg, rows, settings_dict, failures, plots, tuning, sources_text)
        print(f"wrote {out}/results.csv, results.json, report.md" + (f" and {len(plots)} plot files" if plots else ""))
    return 1 if failures or problems else 0


if __name__ == "__main__":
    sys.exit(main())
