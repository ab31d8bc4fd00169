"""``riann-bag-eval``'s outputs, ``--out`` and ``--write-estimates``: checked before any work (what is there, write
permission, files that would be replaced), and written after it from whatever finished, each failure naming its step
and its target (exit status 1), the other outputs still written."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from riann_ros import evaluation as ev
from riann_ros.evaluation import outdir, report, report_files, store
from riann_ros.evaluation.estimate_files import (
    clashes,
    file_stem,
    parse_formats,
    safe,
    write_estimates,
)
from riann_ros.evaluation.input_hints import BROAD_SUFFIXES
from riann_ros.evaluation.results import REFERENCE
from riann_ros.evaluation.scenarios import AS_RECORDED


def err(msg: str) -> None:
    """One line of riann-bag-eval's on stderr (an error, a warning, a note), named after the command."""
    print(f"riann-bag-eval: {msg}", file=sys.stderr, flush=True)


def check(args: argparse.Namespace, inputs: list[str], settings: ev.EvalSettings) -> None:
    """ValueError (exit status 2, before any work) for an output that cannot be written: ``--out`` or
    ``--write-estimates`` not a folder or not writable, or a file ``--write-estimates`` would write that exists
    (without ``--force``), is an input, or two labels or two inputs would share."""
    if args.out is not None:
        outdir.check_folder(args.out, "--out")
    if args.write_estimates is not None:
        outdir.check_folder(args.write_estimates, "--write-estimates")
        problems = _estimate_clashes(args.write_estimates, inputs, settings, parse_formats(args.write_format),
                                     args.force)
        if problems:
            more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
            raise ValueError(f"--write-estimates {args.write_estimates}: {problems[0]}{more}")


def _labels(settings: ev.EvalSettings) -> list[str]:
    """The labels whose trajectory files a run writes (a tuned estimator's aside: its label comes with the tuning)."""
    return [s.label for s in settings.estimators] + [s.label for s in settings.recorded] + [REFERENCE]


def _names(source: str) -> set[str]:
    """The names an input's sequence may get: the file's stem, and the name a converted bag records."""
    p = Path(source)
    names = {p.stem if p.suffix else p.name}
    if p.suffix.lower() not in BROAD_SUFFIXES:
        try:
            from riann_ros import bagio

            recorded = bagio.read_info(p).get("name")
        except Exception:  # unreadable here: the run says why
            recorded = None
        if recorded:
            names.add(str(recorded))
    return names


def _estimate_clashes(folder: Path, inputs: list[str], settings: ev.EvalSettings, formats: tuple[str, ...],
                      force: bool) -> list[str]:
    """What --write-estimates could not write: two labels of one file name; a bag copy that exists, is an input or
    is two inputs' (:func:`~riann_ros.evaluation.estimate_files.clashes`); a trajectory file of an input's expected
    sequence name that exists."""
    by_name: dict[str, list[str]] = {}
    for label in _labels(settings):
        by_name.setdefault(safe(label), []).append(label)
    out = [f"the labels {', '.join(repr(x) for x in same)} give the same file name {name}: give them labels of their "
           "own" for name, same in by_name.items() if len(same) > 1]
    bags = [i for i in inputs if Path(i).suffix.lower() not in BROAD_SUFFIXES]
    out += clashes([folder / Path(i).name for i in bags], inputs, force)
    if not force:
        scenarios = {settings.scenarios[0], AS_RECORDED}
        files = {folder / f"{file_stem(n, s, label)}.{fmt}" for i in inputs for n in _names(i) for s in scenarios
                 for label in _labels(settings) for fmt in formats}
        out += [f"{f} exists: not overwriting it (--force replaces it)" for f in sorted(files) if f.exists()]
    return out


def write_estimate_outputs(results: list[ev.SequenceResult], args: argparse.Namespace) -> list[str]:
    """--write-estimates: the bag copies and trajectory files (all or, on a clash, none), said on stderr (stdout is
    for tables); the problems."""
    out_dir = args.write_estimates
    done = write_estimates(results, out_dir, parse_formats(args.write_format), args.force)
    for dst, topics in done.bags:
        print(f"wrote {dst} ({', '.join(topics)})", file=sys.stderr)
    for src in done.not_bags:
        print(f"{src}: a dataset file, no bag copy (its estimates are in the trajectory files)", file=sys.stderr)
    if done.files:
        names = [p.name for p in done.files]
        print(f"wrote {len(names)} trajectory file(s) in {out_dir}: {', '.join(names)}", file=sys.stderr)
    return [f"--write-estimates: {p}" for p in done.problems]


def write_out(args: argparse.Namespace, rep: report.Report) -> bool:
    """The result files in --out (each figure that cannot be drawn named, the others and the tables still written);
    False when the results could not be written."""
    try:
        written = report_files.write_results(args.out, rep, plots=not args.no_plots, replace=args.force or args.resume)
    except outdir.OutputExists as exc:  # written meanwhile by someone else
        err(str(exc))
        return False
    except OSError as exc:
        shards = args.out / store.SHARDS
        kept = f"; the finished inputs are kept in {shards}: --resume writes them once it can" if shards.is_dir() \
            else ""
        err(f"--out {args.out}: cannot write the results: {exc.strerror or exc}"
             + (f" ({exc.filename})" if exc.filename else "") + kept)
        return False
    for problem in written.problems:
        err(f"--out {args.out}: {problem}")
    print(f"wrote {args.out}/results.csv, results.json, report.md"
          + (f" and {len(written.figures)} plot files" if written.figures else ""))
    return not written.problems
