"""``riann-bag-eval``'s command line: the parser, its options in groups (the run is :mod:`riann_ros.cli.evaluate`).

Option reference: docs/evaluation.md. Every option's help is its documentation on the command line.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from riann_ros import defaults
from riann_ros import evaluation as ev
from riann_ros.evaluation import perturb
from riann_ros.magcal.input import USE_MAG_CHOICES

DEFAULT_ESTIMATORS = "riann,madgwick,mahony,vqf"
#: the options behind each evaluation setting, named when a resumed run asks for other settings (--resume)
SETTING_OPTIONS = {
    "estimators": "--estimators", "scenarios": "--scenarios", "seed": "--seed", "rates": "--rates",
    "conditions": "--perturb", "with_heading": "--heading", "use_mag": "--use-mag",
    "series_for": "--plot-sequence, --no-plots", "series_conditions": "--plot-perturb",
    "keep_estimates": "--write-estimates", "rest": "--rest", "offset_steps": "--offset-steps", "salvage": "--salvage",
    "topics": "--imu-topic, --ground-truth-topic, --estimate-topic, --estimate-file, --t-offset, --max-gap",
    "tune": "--tune", "tune_scenario": "--tune-scenario", "reference_sd_deg": "--reference-sd",
}


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="riann-bag-eval",
        description="Attitude RMSE (e_α, heading ignored) of RIANN, Madgwick, Mahony and VQF on dataset bags, "
        "in the paper's restrictive / partially-restrictive / realistic scenarios and as recorded; also of "
        "estimates your own filter recorded in a bag (--estimate-topic), on any rosbag2 bag (--imu-topic, "
        "--ground-truth-topic); --compare of two saved runs. A bag without a reference orientation (your own robot's) "
        "is run as recorded by every estimator and not scored: what it shows is whether the estimators agree (their "
        "inclination difference, where they part most), the gyro bias each settled on beside the gyro at the "
        "stream's rests, and the stream's health (rate, jitter, holes, rejected samples, unit warnings, restarts), "
        "with a figure of roll, pitch and heading of every estimator; what it cannot show is which estimator is right "
        "where they differ, or an error they share. Full reference: docs/evaluation.md.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="estimator specs: NAME[:PARAM=VALUE[:PARAM=VALUE...]], comma-separated, e.g.\n"
        "  riann,madgwick:beta=0.033,madgwick:beta=0.1,mahony:kp=1:ki=0.3,vqf:tau_acc=3\n"
        "tuning specs: NAME (default grid) or NAME:PARAM=V1/V2/...[:PARAM=...], e.g. mahony:kp=0.5/1/2:ki=0/0.3\n"
        "exit status: 0 ok, 1 some input failed, 2 usage error, 130 interrupted",
    )
    _inputs_and_compare(p)
    _scaling(p)
    _what_runs(p)
    _recorded_estimates(p)
    _conditions(p)
    _results(p)
    _live(p)
    return p


def _inputs_and_compare(p: argparse.ArgumentParser) -> None:
    """The inputs, and ``--compare`` of two saved runs with its row selection."""
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


def _scaling(p: argparse.ArgumentParser) -> None:
    """Many inputs and machines: an input list, a Dask cluster, a resumable --out."""
    s = p.add_argument_group("many inputs and machines (docs/evaluation.md#scaling-out)")
    s.add_argument("--inputs-from", action="append", default=[], metavar="FILE",
                   help="more inputs, read from FILE: one path or glob (*, ?, [...], ** for any depth) per line, in "
                   "that order (a glob's matches sorted); blank lines and lines starting with # are skipped; a "
                   "relative path is relative to FILE's folder ('-': standard input, relative to the current folder). "
                   "A glob that matches nothing is an error. Repeatable; the BAG arguments come first. A file given "
                   "more than once (by its resolved path: a link is its target) is evaluated once, with a warning")
    s.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="evaluate on a Dask cluster instead of --jobs: tcp://HOST:8786 (a scheduler started with "
                   "'dask scheduler', workers with 'dask worker tcp://HOST:8786'; every worker must see the inputs at "
                   "the same paths) or local:N (N worker processes on this machine). Needs pip install "
                   "'riann_ros[cluster]'")
    s.add_argument("--resume", action="store_true",
                   help="continue the run in --out (each finished input is kept in OUT/shards as it completes): "
                   "evaluate only the inputs it has not finished, or that failed, or that changed since (another size, "
                   "modification time or content: said on stderr), then write the result files; refused, naming "
                   "them, when settings differ from that run's")


def _what_runs(p: argparse.ArgumentParser) -> None:
    """The estimators and the scenarios."""
    p.add_argument("--estimators", "-e", default=None,
                   help=f"estimator specs NAME[:PARAM=VALUE...], comma-separated (default: those of "
                   f"{DEFAULT_ESTIMATORS} that are installed); 'none': only the --estimate-topic estimates. PARAM: the "
                   "estimator's, or the magnetometer calibration as the nodes take it: mag_calibration_file=FILE (a "
                   "saved calibration), mag_hard_iron=X/Y/Z (T), mag_soft_iron=D11/.../D33 (a vector's numbers "
                   "between '/'), e.g. riann:mag_calibration_file=my_mag.yaml")
    p.add_argument("--scenarios", "-s", default=None,
                   help="restrictive, partially-restrictive, realistic, as-recorded; paper (the first three) or all "
                   "(comma-separated; default all, or as-recorded with --estimators none)")


def _recorded_estimates(p: argparse.ArgumentParser) -> None:
    """Bags from elsewhere (their topics) and estimates recorded in bags or trajectory files."""
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
                   "file name). FILE may be a glob ('runs/*.tum', quoted) or a folder (its .tum, .csv and .txt files): "
                   "one label for many files, each scored as that estimator on its own input, one row per input and "
                   "one summary row. A file belongs to the input whose file name without suffix (its stem) equals the "
                   "file's stem or starts it followed by a character other than a letter or digit (run1.mcap: "
                   "run1.tum, run1_vins.tum; not run10.tum), the longest such stem; a single file with a single "
                   "input belongs to it whatever its name. Inputs without a file and files without an input are "
                   "warned about. An estimate covering less than 90 %% of an input's scored span is scored over what "
                   "it covers but not ranked (left out of the summary, with a warning). Repeatable")
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


def _conditions(p: argparse.ArgumentParser) -> None:
    """What the estimators run under: perturbations, salvaged bags, the initial rest, the seed, rates, workers."""
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
    p.add_argument("--score-from", type=float, default=0.0, metavar="SECONDS",
                   help="score every metric only from SECONDS after each sequence's first sample (e.g. the heading "
                        "after a magnetometer calibration has converged); recorded in results.json")
    p.add_argument("--reference-sd", type=float, default=0.0, metavar="DEG",
                   help="the reference's own error per axis (1σ, degrees; default 0: the reference taken as exact), "
                   "e.g. an optical system's marker and alignment error, which no estimator's σ should carry: the "
                   "uncertainty scores (95 %% coverage, NEES, inclination and heading) are taken against "
                   "σ² = σ_estimator² + σ_ref² per axis; shown in the uncertainty tables, recorded in results.json")
    p.add_argument("--seed", type=int, default=0, help="seed of the random gyro bias (per sequence: seed + name)")
    p.add_argument("--rates", default=None,
                   help="comma-separated sampling rates (Hz) to resample to (FFT), e.g. 50,100,200,500; 'native' "
                   "keeps the recording's own rate. Native-rate runs stream bags chunk by chunk (memory independent "
                   "of the bag length); resampled runs load each input whole")
    p.add_argument("--jobs", "-j", type=int, default=1, help="parallel worker processes (one per sequence)")


def _results(p: argparse.ArgumentParser) -> None:
    """What is scored and written: the output folder, heading, magnetometer, time offsets, plots, tuning."""
    p.add_argument("--out", "-o", type=Path, default=None,
                   help="write results.csv, results.json, report.md and plots (PNG+SVG) here (a folder already holding "
                   "results needs --force; it must be a folder, or not exist, and be writable: checked before any "
                   "work)")
    p.add_argument("--heading", action="store_true",
                   help="also score heading and total error of 6D runs (unaligned, as evo_ape without alignment: they "
                   "include the start heading) and the heading drift (heading_drift_*: the heading error after "
                   "aligning the estimate's heading with the reference's at the first scored sample), which the "
                   "tables show for 6D runs; 9D runs always have heading and total error")
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
                   help="write into DIR a copy of every input bag with each estimator's output as "
                   "geometry_msgs/QuaternionStamped topics /eval/<scenario>/<estimator> (first scenario), and per "
                   "input and estimator a trajectory file <sequence>.<scenario>.<label>.tum (TUM: t x y z qx qy qz "
                   "qw, position 0 0 0; evo_ape / evo_traj read it), plus <sequence>.<scenario>.reference.tum with "
                   "the reference at the scored samples where the input has one. A file that exists (without --force) "
                   "is refused before any work; after the run all files are written or, on a clash, none. Combines "
                   "with --resume")
    p.add_argument("--write-format", default="tum", metavar="tum|csv|tum,csv",
                   help="the trajectory files of --write-estimates: tum (default), csv (a header time[s],qw,qx,qy,qz: "
                   "what --estimate-file reads) or both")
    p.add_argument("--force", action="store_true",
                   help="replace an earlier run's result files in --out (results.csv/json, report.md, compare.csv and "
                   "the plots; nothing else in the folder) and existing --write-estimates bags; without it an --out "
                   "folder holding results is refused before any work")


def _live(p: argparse.ArgumentParser) -> None:
    """``--live``: the replay over DDS to the estimator nodes; and the progress bar."""
    p.add_argument("--live", action="store_true",
                   help="replay the inputs over DDS to the estimator nodes (started by the tool, or already running "
                   "with --live-topics) instead of running them in-process; reports messages lost")
    p.add_argument("--speed", type=float, default=1.0, help="--live replay speed factor (0: as fast as the nodes go)")
    p.add_argument("--live-input", default=None,
                   help="--live: IMU topic to publish on (sensor_msgs/Imu; default /riann_eval/imu/data_raw)")
    p.add_argument("--live-mag", default=None,
                   help="--live: magnetometer topic to publish an input's field on (sensor_msgs/MagneticField at the "
                   "samples' stamps, unless --use-mag false; default /riann_eval/imu/mag)")
    p.add_argument("--live-topics", default=None,
                   help="--live with nodes already running: their attitude topics, comma-separated, in --estimators "
                   "order (they must subscribe to --live-input, and to --live-mag for the field); a topic without "
                   "its node after 10 s stops the run, naming it")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bar (nor --live's progress lines)")
