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
This module turns the command line (:mod:`riann_ros.cli.evaluate_parser`) into settings and prints; the work is
one library call, :func:`riann_ros.evaluation.session.evaluate`. Where the inputs run (the executor setting) and the
runner of ``--live``: :mod:`riann_ros.cli.eval_executor`.
"""

from __future__ import annotations

import argparse
import math
import shlex
import sys
import time

from riann_ros import evaluation as ev
from riann_ros.cli import eval_executor, eval_inputs, eval_outputs, input_lists
from riann_ros.cli.evaluate_parser import DEFAULT_ESTIMATORS, SETTING_OPTIONS, build_parser
from riann_ros.cli.pipe import quiet_when_reader_leaves
from riann_ros.cli.progress import Progress
from riann_ros.evaluation import coverage, free_report, outdir, perturb, report, seq_tables, session, store
from riann_ros.evaluation.estimate_files import parse_formats
from riann_ros.evaluation.fleet import Scale
from riann_ros.evaluation.uncertainty_report import format_uncertainty_table


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


def _settings(args: argparse.Namespace, warnings: list[str] | None = None) -> ev.EvalSettings:
    """The evaluation settings of the command line (ValueError / ImportError on bad usage); ``warnings``: found in the
    inputs already (inputs given twice), the first of its input warnings."""
    parse_formats(args.write_format)
    if args.tune_scenario not in ev.SCENARIOS:
        raise ValueError(f"unknown --tune-scenario {args.tune_scenario!r}; known: {', '.join(ev.SCENARIOS)}")
    for t in args.tune:
        ev.parse_grid(t)
    _check_resume(args)
    if not 0 <= args.offset_steps <= 50:
        raise ValueError("--offset-steps must be 0 (no search) to 50")
    if not (math.isfinite(args.reference_sd) and args.reference_sd >= 0.0):
        raise ValueError(f"--reference-sd must be a finite angle of at least 0 (degrees), got {args.reference_sd:g}")
    have = ev.available_estimators()
    spec_text = args.estimators or ",".join(n for n in DEFAULT_ESTIMATORS.split(",") if n in have)
    only_recorded = spec_text.strip().lower() == "none"
    input_warnings = list(warnings or [])
    topics = eval_inputs.topics(args, input_warnings)
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
        score_from_s=args.score_from,
        reference_sd_deg=args.reference_sd,
        input_warnings=input_warnings,
    )
    eval_inputs.check_recorded(settings)
    return settings


def _check_resume(args: argparse.Namespace) -> None:
    """--resume with the options it goes with (ValueError otherwise)."""
    if args.resume and not args.out:
        raise ValueError("--resume continues the run kept in an --out folder: give --out")
    if args.resume and args.force:
        raise ValueError("--resume does not combine with --force (which starts over)")


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


def _hooks(args: argparse.Namespace, n_sources: int) -> session.Hooks:
    """The run's messages on stderr: each tuning search (unless --quiet) and its best; the progress bar."""

    def tuning(text: str) -> None:
        if not args.quiet:
            eval_outputs.err(f"tuning {text} on {n_sources} input(s), {args.tune_scenario}")

    def tuned(best: dict) -> None:
        b = best["best"]
        eval_outputs.err(f"tuned {best['estimator']} on {args.tune_scenario}: {b['label']} mean {b['mean']:.2f}° "
             f"max {b['max']:.2f}°")

    def note(text: str) -> None:
        if not args.quiet:
            eval_outputs.err(text)

    return session.Hooks(tuning=tuning, tuned=tuned, progress=lambda n: Progress(n, enabled=not args.quiet),
                         note=note)


def _print_free(rep: report.Report) -> None:
    """The inputs without a reference: which they are, the estimators' agreement, their bias, the stream's health."""
    which = free_report.which_is_which(rep.results)
    if not which:
        return
    print(f"\ninputs {which}")
    for table in (free_report.format_agreement(rep.results), free_report.format_bias(rep.results, rep.rows),
                  free_report.format_health(rep.results)):
        if table:
            print("\n" + table)


def _print_summary(rep: report.Report, live: bool) -> None:
    if rep.summary or all(r.has_reference for r in rep.results):
        print(report.format_table(rep.summary))
        for line in coverage.recorded_lines(rep.rows):
            print(line)
    _print_free(rep)
    nine = seq_tables.format_heading_table(rep.rows)
    if nine:
        print("\n" + nine)
    for err in ev.ERRORS:
        table = seq_tables.format_stats_table(rep.rows, err, limit=report.PRINT_ROWS)
        if table:
            print("\n" + table)
    for note in rep.timing_notes:
        print(f"\ntiming: {note}")
    unc = format_uncertainty_table(rep.rows, reference_sd_deg=rep.settings.reference_sd_deg)
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
    n_free = sum(1 for r in rep.results if not r.error and not r.has_reference)
    print(f"\n{len(rep.results) - n_fail} of {len(rep.results)} input(s) evaluated in {rep.elapsed_s:.1f} s"
          + (f" ({n_free} without a reference: not scored)" if n_free else "")
          + (f"; {n_fail} failed" if n_fail else ""))


def main(argv: list[str] | None = None) -> int:
    """The CLI. Ctrl-C exits with status 130 and a one-line message, leaving no result files of this run. A reader
    that closes stdout early (``| head``) ends only the printing: the result files are still written."""
    try:
        with quiet_when_reader_leaves():
            return _main(argv)
    except KeyboardInterrupt as exc:  # its text: what the run kept (_evaluate)
        eval_outputs.err(str(exc) or "interrupted; no result files written")
        return 130


def _mode(args: argparse.Namespace) -> str:
    return store.RESUME if args.resume else store.REPLACE if args.force else store.NEW


def _check_out(args: argparse.Namespace, run: session.EvalRun | None = None) -> None:
    """Refuse (ValueError, exit status 2) an --out folder holding an earlier run's results, or another run's kept
    inputs (``run``: this run, whose settings a resumed run must share), and outputs that cannot be written
    (:func:`riann_ros.cli.eval_outputs.check`), before any work."""
    old = outdir.previous_results(args.out) if args.out and not (args.force or args.resume) else []
    if old:
        raise ValueError(str(outdir.OutputExists(args.out, old)))
    if run is None:
        return
    if args.out:
        store.check(args.out, store.fingerprint(run.settings, run.tune, run.tune_scenario), _mode(args),
                    SETTING_OPTIONS)
    eval_outputs.check(args, list(run.sources), run.settings)


def _print_messages(rep: report.Report) -> None:
    """Warnings and failures on stderr, then the summary table on stdout."""
    if rep.settings.series_for not in (None, "*", "all") and not any(r.series for r in rep.results):
        eval_outputs.err(f"--plot-sequence {rep.settings.series_for!r} matches no evaluated sequence")
    for w in rep.settings.input_warnings:
        eval_outputs.err(f"warning: {w}")
    for res in rep.results:
        for w in res.warnings if not res.error else []:
            eval_outputs.err(f"warning: {w}")
    for w in coverage.warnings(rep.rows):
        eval_outputs.err(f"warning: {w}")
    for f in rep.failures:
        eval_outputs.err(f"FAILED {f['error']}")


def _compare(args: argparse.Namespace) -> int:
    """``--compare A B``: print (and with --out write) the difference of two saved runs; no estimator runs."""
    from riann_ros.evaluation import compare as cp
    from riann_ros.evaluation import compare_text

    try:
        _check_out(args)
        both = cp.parse_selection(args.select)
        sel_a = cp.Selection(both.items + cp.parse_selection(args.select_a).items)
        sel_b = cp.Selection(both.items + cp.parse_selection(args.select_b).items)
        metric = cp.parse_metric(args.metric)
    except ValueError as exc:
        eval_outputs.err(str(exc))
        return 2
    try:
        cmp = cp.compare(cp.load(args.compare[0]), cp.load(args.compare[1]), sel_a, sel_b, metric)
    except ev.EvalError as exc:
        eval_outputs.err(str(exc))
        return 1
    print(compare_text.format_comparison(cmp))
    if args.out:
        try:
            files = cp.write_comparison(args.out, cmp, plots=not args.no_plots, replace=args.force)
        except outdir.OutputExists as exc:
            eval_outputs.err(str(exc))
            return 1
        print(f"wrote {', '.join(str(f) for f in files)}")
    return 0


def _evaluate(args: argparse.Namespace, run: session.EvalRun) -> report.Report | None:
    """The run (None: it could not go on, said on stderr). Interrupted: what the --out folder keeps, then
    KeyboardInterrupt."""
    started = time.perf_counter()  # the run's time includes the start of the --live nodes
    try:
        with eval_executor.runner(args) as runner:
            return session.evaluate(run, runner, _hooks(args, len(run.sources)), started)
    except ev.EvalError as exc:
        eval_outputs.err(str(exc))
    except OSError as exc:  # the shards of --out no longer writable, say
        kept = f"; the inputs finished so far are kept in {args.out / store.SHARDS}" if args.out else ""
        where = f" ({exc.filename})" if exc.filename else ""
        eval_outputs.err(f"the run stopped: {exc.strerror or exc}{where}{kept}")
    except KeyboardInterrupt:
        if args.out and (args.out / store.SHARDS).is_dir():
            raise KeyboardInterrupt(f"interrupted; no result files written; the inputs finished so far are kept in "
                                    f"{args.out / store.SHARDS}: add --resume to continue") from None
        raise
    return None


def _main(argv: list[str] | None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    argv_list = sys.argv[1:] if argv is None else list(argv)
    if args.compare is not None:
        if args.inputs or args.inputs_from:
            parser.error("--compare A B takes no inputs: it compares two saved runs")
        return _compare(args)
    try:
        given = [*map(str, args.inputs), *input_lists.inputs_from(args.inputs_from)]
    except ValueError as exc:
        eval_outputs.err(str(exc))
        return 2
    inputs, twice = input_lists.deduplicated(given)
    args.inputs = inputs
    if not inputs:
        parser.error("no input given (bags or BROAD files, --inputs-from FILE; or --compare A B)")
    if args.select or args.select_a or args.select_b or args.metric != "rmse":
        parser.error("--select, --select-a, --select-b and --metric belong to --compare A B")
    try:
        scale = Scale(eval_executor.executor_setting(args), args.out, _mode(args))
        run = session.EvalRun(tuple(inputs), _settings(args, twice), tuple(args.tune), args.tune_scenario,
                              "riann-bag-eval " + shlex.join(argv_list), scale)
        _check_out(args, run)
    except (ValueError, ImportError) as exc:
        eval_outputs.err(str(exc))
        return 2
    if args.resume:
        for src, why in store.stale(args.out, inputs):
            eval_outputs.err(f"warning: {src} changed since the earlier run in {args.out} ({why}): evaluated again")
    rep = _evaluate(args, run)
    return 1 if rep is None else _finish(args, rep)


def _finish(args: argparse.Namespace, rep: report.Report) -> int:
    """The messages and tables, then every output written from what finished (one failing does not stop the
    others); exit status 1 when an input or an output failed."""
    _print_messages(rep)
    _print_summary(rep, args.live)
    written = eval_outputs.write_out(args, rep) if args.out else True
    problems = eval_outputs.write_estimate_outputs(rep.results, args) if args.write_estimates else []
    for p in problems:
        eval_outputs.err(p)
    return 1 if rep.failures or problems or not written else 0


if __name__ == "__main__":
    sys.exit(main())
