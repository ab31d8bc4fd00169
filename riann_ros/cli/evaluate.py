"""``riann-bag-eval``: score attitude estimators on dataset bags the paper's way.

Example::

    riann-bag-eval bags/*.mcap --estimators riann,madgwick:beta=0.033,mahony:kp=1:ki=0.3,vqf \\
        --scenarios all --seed 0 --jobs 2 --out eval_out

    riann-bag-eval my.mcap --imu-topic /imu --ground-truth-topic /mocap/pose --estimate-topic /my_filter/imu
    riann-bag-eval --compare eval_a/results.json eval_b/results.json --out a_vs_b

Inputs are rosbag2 bags in the layout of :mod:`riann_ros.bagio` (``.mcap`` files or bag directories), any
rosbag2 bag with ``--imu-topic`` / ``--ground-truth-topic``, or BROAD trial files (``.hdf5`` / ``.mat``).
Full reference: docs/evaluation.md. Exit status: 0 all inputs evaluated, 1 some input failed
(named on stderr, the others are still evaluated and reported), 130 interrupted, 2 bad command line.
This module only parses the command line and prints; the work is in :mod:`riann_ros.evaluation`
(and :mod:`riann_ros.cli.live` for ``--live``).
"""

from __future__ import annotations

import argparse
import re
import shlex
import sys
import time
from pathlib import Path

from riann_ros import defaults
from riann_ros import evaluation as ev
from riann_ros.cli import eval_inputs
from riann_ros.cli.pipe import quiet_when_reader_leaves
from riann_ros.evaluation import outdir, perturb, report, seq_tables
from riann_ros.evaluation.uncertainty_report import format_uncertainty_table
from riann_ros.mag import USE_MAG_CHOICES

DEFAULT_ESTIMATORS = "riann,madgwick,mahony,vqf"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="riann-bag-eval",
        description="Attitude RMSE (e_α, heading ignored) of RIANN, Madgwick, Mahony and VQF on dataset bags, "
        "in the paper's restrictive / partially-restrictive / realistic scenarios and as recorded; also of "
        "estimates your own filter recorded in a bag (--estimate-topic), on any rosbag2 bag (--imu-topic, "
        "--ground-truth-topic); --compare of two saved runs. Full reference: docs/evaluation.md.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="estimator specs: NAME[:PARAM=VALUE[:PARAM=VALUE...]], comma-separated, e.g.\n"
        "  riann,madgwick:beta=0.033,madgwick:beta=0.1,mahony:kp=1:ki=0.3,vqf:tau_acc=3\n"
        "tuning specs: NAME (default grid) or NAME:PARAM=V1/V2/...[:PARAM=...], e.g. mahony:kp=0.5/1/2:ki=0/0.3\n"
        "exit status: 0 ok, 1 some input failed, 2 usage error, 130 interrupted",
    )
    p.add_argument("inputs", nargs="*", metavar="BAG",
                   help="bags (.mcap, .db3, bag directories) or BROAD .hdf5/.mat files (CSV files and EuRoC folders: "
                   "convert them with riann-bag-convert first; the error message says how)")
    c = p.add_argument_group("comparing saved runs (evo_res style)")
    c.add_argument("--compare", nargs=2, metavar=("A", "B"), type=Path, default=None,
                   help="no evaluation: the difference B − A of two saved runs (results.json files or their --out "
                   "folders; the same run twice to compare rows of one run), paired by sequence and by every axis "
                   "(estimator, scenario, perturbation, rate) on which A and B share a value; per group "
                   "(mean/median/max) and per sequence; with --out, compare.csv and the plot compare_rmse")
    c.add_argument("--select-a", action="append", default=[], metavar="FIELD=VALUE",
                   help="--compare: only A's rows with this value (estimator, scenario, perturbation, rate, sequence, "
                   "dataset, sensors; estimator: a table label or a spec as for -e). Repeatable")
    c.add_argument("--select-b", action="append", default=[], metavar="FIELD=VALUE",
                   help="--compare: only B's rows with this value (as --select-a)")
    c.add_argument("--select", action="append", default=[], metavar="FIELD=VALUE",
                   help="--compare: only rows with this value, on both sides")
    c.add_argument("--metric", default="rmse",
                   help="--compare: the per-sequence statistic compared: rmse (default), mean, median, std, min, max "
                   "of e_α; heading_rmse, heading_mean, …, total_rmse, … where scored")
    p.add_argument("--estimators", "-e", default=None,
                   help=f"estimator specs (default: those of {DEFAULT_ESTIMATORS} that are installed); 'none': only "
                   "the --estimate-topic estimates")
    p.add_argument("--scenarios", "-s", default=None,
                   help="restrictive, partially-restrictive, realistic, as-recorded; paper (the first three) or all "
                   "(comma-separated; default all, or as-recorded with --estimators none)")
    b = p.add_argument_group("bags from elsewhere and estimates recorded in them (evo style)")
    b.add_argument("--estimate-topic", action="append", default=[], metavar="TOPIC",
                   help="score the orientation a filter recorded on TOPIC in the bag (sensor_msgs/Imu, geometry_msgs/"
                   "QuaternionStamped, PoseStamped, PoseWithCovarianceStamped, nav_msgs/Odometry) against the ground "
                   "truth, beside the built-in estimators; matched to the IMU samples by stamp (slerp between "
                   "messages). It is the recording as it is, so it is scored in the as-recorded scenario only, at the "
                   "native rate, unperturbed. Repeatable")
    b.add_argument("--estimate-file", action="append", default=[], metavar="FILE[:LABEL]",
                   help="score an estimate in a trajectory file against the input's reference, like --estimate-topic: "
                   "a TUM file (t tx ty tz qx qy qz qw, t in seconds, no header) or a CSV with a header: a time "
                   "column (timestamp, time or t; its unit in the name, e.g. time[s], else ns) and qw, qx, qy, qz "
                   "(the IMU frame's orientation in a z-up world, as the reference). Labelled LABEL (default: the "
                   "file name). With several inputs a file belongs to the input whose name starts its name "
                   "(run1.mcap: run1_vins.tum). Repeatable")
    b.add_argument("--estimate-cols", default=None, metavar="TIME,QW,QX,QY,QZ",
                   help="the --estimate-file columns, for a CSV in another layout")
    b.add_argument("--estimate-time-unit", default=None, choices=("s", "ms", "us", "ns"),
                   help="the time unit of the --estimate-file stamps (default: from the column name; ns for a CSV, "
                   "s for a TUM file)")
    b.add_argument("--t-offset", type=float, default=0.0, metavar="SECONDS",
                   help="added to the stamps of the --estimate-topic and --estimate-file estimates before matching "
                   "(default 0)")
    b.add_argument("--max-gap", type=float, default=defaults.MAX_GAP_S, metavar="SECONDS",
                   help="slerp a topic between two messages at most this far apart, hold the nearer one within half "
                   "of it, else the sample has none (not scored, counted as unestimated); --estimate-topic and "
                   f"--ground-truth-topic (default {defaults.MAX_GAP_S})")
    b.add_argument("--ground-truth-topic", default=None, metavar="TOPIC",
                   help="the reference orientation for bags not written by riann-bag-convert (geometry_msgs/"
                   "PoseStamped, nav_msgs/Odometry, geometry_msgs/QuaternionStamped, sensor_msgs/Imu, …; the IMU "
                   "frame's orientation in a z-up world), interpolated onto the IMU stamps")
    b.add_argument("--imu-topic", default=None, metavar="TOPIC",
                   help="the sensor_msgs/Imu topic of the samples (default /imu/data_raw); without a "
                   "/ground_truth/scored topic every sample is scored")
    p.add_argument("--perturb", "-p", action="append", default=[], metavar="CONDITION",
                   help="evaluate under this condition too: 'none', or perturbations joined with '+': "
                   f"{perturb.accepted_forms()}; repeatable, each one a condition (default: none; "
                   "docs/evaluation.md#perturbations)")
    p.add_argument("--salvage", action="store_true",
                   help="score the readable part of a bag cut off by a crash or a full disk (an MCAP file without its "
                   "footer, a sqlite3 file shorter than its header says), saying how much was recovered; without it "
                   "such a bag fails with that count (riann-bag-convert --repair writes a repaired copy)")
    p.add_argument("--rest", default=None, metavar="START:END",
                   help="the initial rest, in seconds from the first sample, whose mean gyro is removed as the turn-on "
                   "bias (default: detected from the signals before the first scored sample; see docs/evaluation.md)")
    p.add_argument("--seed", type=int, default=0, help="seed of the random gyro bias (per sequence: seed + name)")
    p.add_argument("--rates", default=None,
                   help="comma-separated sampling rates (Hz) to resample to (FFT), e.g. 50,100,200,500; 'native' "
                   "keeps the recording's own rate. Native-rate runs stream bags chunk by chunk (memory independent "
                   "of the bag length); resampled runs load each input whole")
    p.add_argument("--jobs", "-j", type=int, default=1, help="parallel worker processes (one per sequence)")
    p.add_argument("--out", "-o", type=Path, default=None,
                   help="write results.csv, results.json, report.md and plots (PNG+SVG) here (a folder already holding "
                   "results needs --force)")
    p.add_argument("--heading", action="store_true",
                   help="also score heading and total error of 6D runs (heading drift; 9D runs always have them)")
    p.add_argument("--use-mag", choices=USE_MAG_CHOICES, default="auto",
                   help="the magnetometer (/imu/mag), as the nodes' use_mag: auto (default) = every estimator runs 9D "
                   "where the recording has a field, with heading and total error in the results; false = 6D only")
    p.add_argument("--offset-steps", type=int, default=ev.OFFSET_STEPS, metavar="STEPS",
                   help="per estimator and sequence, find the time offset (added to the estimate stamps, like "
                   "--t-offset) that minimises the e_α RMSE within ± STEPS steps of the stream, and the RMSE there; "
                   f"in the as-recorded scenario, else the first (default {ev.OFFSET_STEPS}; 0: no search)")
    p.add_argument("--plot-perturb", action="append", default=[], metavar="CONDITION",
                   help="plot this --perturb condition (repeatable; default: every condition, each in panels or "
                   "figures of its own)")
    p.add_argument("--plot-sequence", default=None,
                   help="sequence for the error-over-time and roll/pitch plots (default: the first input); 'all': "
                   "a roll/pitch figure (roll_pitch_<sequence>) for every sequence")
    p.add_argument("--no-plots", action="store_true", help="skip the plots")
    p.add_argument("--tune", action="append", default=[], metavar="SPEC",
                   help="grid-search this estimator's parameters for the lowest mean RMSE on the inputs and add "
                   "the best one to the comparison (repeatable)")
    p.add_argument("--tune-scenario", default=ev.REALISTIC, help="scenario the tuning minimises (default realistic)")
    p.add_argument("--write-estimates", type=Path, default=None, metavar="DIR",
                   help="write a copy of every input bag into DIR with each estimator's output as "
                   "geometry_msgs/QuaternionStamped topics /eval/<scenario>/<estimator> (first scenario)")
    p.add_argument("--force", action="store_true",
                   help="replace an earlier run's result files in --out (results.csv/json, report.md, compare.csv and "
                   "the plots; nothing else in the folder) and existing --write-estimates bags; without it an --out "
                   "folder holding results is refused before any work")
    p.add_argument("--live", action="store_true",
                   help="replay the inputs over DDS to the estimator nodes (started by the tool, or already running "
                   "with --live-topics) instead of running them in-process; reports messages lost")
    p.add_argument("--speed", type=float, default=1.0, help="--live replay speed factor (0: as fast as the nodes go)")
    p.add_argument("--live-input", default=None,
                   help="--live: IMU topic to publish on (default /riann_eval/imu/data_raw)")
    p.add_argument("--live-topics", default=None,
                   help="--live with nodes already running: their attitude topics, comma-separated, in --estimators "
                   "order (they must subscribe to --live-input)")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bar")
    return p


def parse_rates(text: str | None) -> list[float | None]:
    if not text:
        return [None]
    out: list[float | None] = []
    for item in (s.strip().lower() for s in text.split(",")):
        if item == "native":
            out.append(None)
        elif item:
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


def _settings(args: argparse.Namespace) -> ev.EvalSettings:
    """The evaluation settings of the command line (ValueError / ImportError on bad usage)."""
    if args.live and (args.tune or args.jobs > 1 or args.write_estimates):
        raise ValueError("--live runs one replay at a time: it does not combine with --tune, --jobs or "
                         "--write-estimates")
    if args.tune_scenario not in ev.SCENARIOS:
        raise ValueError(f"unknown --tune-scenario {args.tune_scenario!r}; known: {', '.join(ev.SCENARIOS)}")
    for t in args.tune:
        ev.parse_grid(t)
    if args.jobs < 1:
        raise ValueError("--jobs must be at least 1")
    if not 0 <= args.offset_steps <= 50:
        raise ValueError("--offset-steps must be 0 (no search) to 50")
    have = ev.available_estimators()
    spec_text = args.estimators or ",".join(n for n in DEFAULT_ESTIMATORS.split(",") if n in have)
    only_recorded = spec_text.strip().lower() == "none"
    topics = eval_inputs.topics(args)
    if only_recorded and not (topics.estimates or topics.files):
        raise ValueError("--estimators none needs at least one --estimate-topic or --estimate-file")
    settings = ev.EvalSettings(
        estimators=[] if only_recorded else ev.parse_estimators(spec_text),
        scenarios=ev.parse_scenarios(args.scenarios or (ev.AS_RECORDED if only_recorded else "all")),
        seed=args.seed,
        rates=parse_rates(args.rates),
        conditions=[ev.parse_condition(c) for c in args.perturb] or [ev.Condition()],
        with_heading=args.heading,
        use_mag=args.use_mag,
        series_for=None if args.no_plots or not args.out else (args.plot_sequence or "*"),
        series_conditions=_plotted(args),
        keep_estimates=args.write_estimates is not None,
        rest=ev.parse_rest(args.rest) if args.rest else None,
        topics=topics,
        offset_steps=args.offset_steps,
        salvage=args.salvage,
    )
    eval_inputs.check_recorded(settings)
    return settings


def _plotted(args: argparse.Namespace) -> tuple[str, ...] | None:
    """The condition labels of --plot-perturb (None: every condition); ValueError for one not evaluated."""
    if not args.plot_perturb:
        return None
    evaluated = [ev.parse_condition(c).label for c in args.perturb] or [perturb.NONE]
    labels = tuple(ev.parse_condition(c).label for c in args.plot_perturb)
    unknown = [lbl for lbl in labels if lbl not in evaluated]
    if unknown:
        raise ValueError(f"--plot-perturb {unknown[0]} is not an evaluated condition (--perturb: "
                         f"{', '.join(evaluated)})")
    return labels


def _tune(args: argparse.Namespace, sources: list[str], settings: ev.EvalSettings) -> list[dict]:
    tuning = []
    for text in args.tune:
        if not args.quiet:
            _err(f"tuning {text} on {len(sources)} input(s), {args.tune_scenario}")
        best, spec = ev.tune(text, sources, args.tune_scenario, settings.seed, args.jobs,
                             report.Progress(len(sources), enabled=not args.quiet), like=settings)
        tuning.append(best)
        b = best["best"]
        _err(f"tuned {best['estimator']} on {args.tune_scenario}: {b['label']} mean {b['mean']:.2f}° "
             f"max {b['max']:.2f}°")
        if spec.label not in {e.label for e in settings.estimators}:
            settings.estimators.append(spec)
    return tuning


def _evaluate(args: argparse.Namespace, sources: list[str], settings: ev.EvalSettings) -> list[ev.SequenceResult]:
    progress = report.Progress(len(sources), enabled=not args.quiet)
    if not args.live:
        return ev.evaluate_sources(sources, settings, args.jobs, progress)
    try:
        from riann_ros.cli.live import LiveRunner
    except ImportError as exc:
        raise ev.EvalError(f"--live needs rclpy and the ROS message packages: {exc}") from exc
    topics = args.live_topics.split(",") if args.live_topics else None
    with LiveRunner(speed=args.speed, input_topic=args.live_input, topics=topics) as runner:
        return ev.evaluate_sources(sources, settings, 1, progress, runner)


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


def _print_summary(rep: report.Report, live: bool) -> None:
    print(report.format_table(rep.summary))
    nine = seq_tables.format_heading_table(rep.rows)
    if nine:
        print("\n" + nine)
    for err in ev.ERRORS:
        table = seq_tables.format_stats_table(rep.rows, err, limit=report.PRINT_ROWS)
        if table:
            print("\n" + table)
    for note in rep.timing_notes:
        print(f"\ntiming: {note}")
    unc = format_uncertainty_table(rep.rows)
    if unc:
        print("\n" + unc)
    rows = rep.rows
    if live and rows:
        lost: dict[str, list[int]] = {}
        for row in rows:
            v = lost.setdefault(row.estimator, [0, 0])
            live_stats = row.stats.live or {}
            v[0] += live_stats.get("lost", 0)
            v[1] += live_stats.get("published", 0)
        print("live: messages lost / published: " + ", ".join(f"{k} {a} / {b}" for k, (a, b) in lost.items()))
    n_fail = len(rep.failures)
    print(f"\n{len(rep.results) - n_fail} of {len(rep.results)} input(s) evaluated in {rep.elapsed_s:.1f} s"
          + (f"; {n_fail} failed" if n_fail else ""))


def main(argv: list[str] | None = None) -> int:
    """The CLI. Ctrl-C exits with status 130 and a one-line message, leaving no result files of this run. A reader
    that closes stdout early (``| head``) ends only the printing: the result files are still written."""
    try:
        with quiet_when_reader_leaves():
            return _main(argv)
    except KeyboardInterrupt:
        _err("interrupted; no results written")
        return 130


def _check_out(args: argparse.Namespace) -> None:
    """Refuse (ValueError, exit status 2) an --out folder holding an earlier run's results, before any work."""
    old = outdir.previous_results(args.out) if args.out and not args.force else []
    if old:
        raise ValueError(str(outdir.OutputExists(args.out, old)))


def _print_messages(rep: report.Report) -> None:
    """Warnings and failures on stderr, then the summary table on stdout."""
    if rep.settings.series_for not in (None, "*", "all") and not any(r.series for r in rep.results):
        _err(f"--plot-sequence {rep.settings.series_for!r} matches no evaluated sequence")
    for res in rep.results:
        for w in res.warnings if not res.error else []:
            _err(f"warning: {w}")
    for f in rep.failures:
        _err(f"FAILED {f['error']}")


def _write_out(args: argparse.Namespace, rep: report.Report) -> bool:
    """The result files in --out; False when they could not be written."""
    try:
        figures = report.write_results(args.out, rep, plots=not args.no_plots, replace=args.force)
    except outdir.OutputExists as exc:  # written meanwhile by someone else
        _err(str(exc))
        return False
    print(f"wrote {args.out}/results.csv, results.json, report.md"
          + (f" and {len(figures)} plot files" if figures else ""))
    return True


def _compare(args: argparse.Namespace) -> int:
    """``--compare A B``: print (and with --out write) the difference of two saved runs; no estimator runs."""
    from riann_ros.evaluation import compare as cp
    from riann_ros.evaluation import compare_text

    try:
        both = cp.parse_selection(args.select)
        sel_a = cp.Selection(both.items + cp.parse_selection(args.select_a).items)
        sel_b = cp.Selection(both.items + cp.parse_selection(args.select_b).items)
        metric = cp.parse_metric(args.metric)
    except ValueError as exc:
        _err(str(exc))
        return 2
    try:
        cmp = cp.compare(cp.load(args.compare[0]), cp.load(args.compare[1]), sel_a, sel_b, metric)
    except ev.EvalError as exc:
        _err(str(exc))
        return 1
    print(compare_text.format_comparison(cmp))
    if args.out:
        try:
            files = cp.write_comparison(args.out, cmp, plots=not args.no_plots, replace=args.force)
        except outdir.OutputExists as exc:
            _err(str(exc))
            return 1
        print(f"wrote {', '.join(str(f) for f in files)}")
    return 0


def _main(argv: list[str] | None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    argv_list = sys.argv[1:] if argv is None else list(argv)
    if args.compare is not None:
        if args.inputs:
            parser.error("--compare A B takes no inputs: it compares two saved runs")
        try:
            _check_out(args)
        except ValueError as exc:
            _err(str(exc))
            return 2
        return _compare(args)
    if not args.inputs:
        parser.error("no input given (bags or BROAD files; or --compare A B)")
    if args.select or args.select_a or args.select_b or args.metric != "rmse":
        parser.error("--select, --select-a, --select-b and --metric belong to --compare A B")
    try:
        settings = _settings(args)
        _check_out(args)
    except (ValueError, ImportError) as exc:
        _err(str(exc))
        return 2
    sources = [str(s) for s in args.inputs]
    t_start = time.perf_counter()
    try:
        tuning = _tune(args, sources, settings)
        results = _evaluate(args, sources, settings)
    except ev.EvalError as exc:
        _err(str(exc))
        return 1
    rep = report.Report("riann-bag-eval " + shlex.join(argv_list), sources, settings, results,
                        time.perf_counter() - t_start, args.jobs, tuning)
    _print_messages(rep)
    _print_summary(rep, args.live)
    problems = _write_estimates(results, args.write_estimates, args.force) if args.write_estimates else []
    for p in problems:
        _err(p)
    if args.out and not _write_out(args, rep):
        return 1
    return 1 if rep.failures or problems else 0


if __name__ == "__main__":
    sys.exit(main())
