"""``riann-bag-eval``'s executor options: where the inputs run, decided from ``--live``, ``--scheduler`` and
``--jobs`` as an explicit :class:`~riann_ros.evaluation.executors.ExecutorSetting`, and the runner of ``--live``
(the evaluator's runner over the ROS layer's DDS replay: this module wires them, importing no ROS package itself)."""

from __future__ import annotations

import argparse
from contextlib import AbstractContextManager, nullcontext

from riann_ros import evaluation as ev
from riann_ros.cli.eval_outputs import err
from riann_ros.evaluation import executors
from riann_ros.evaluation.live import LiveRunner
from riann_ros.evaluation.runners import Runner
from riann_ros.replay import ReplayError

# why --live runs in this process, whatever else is asked
LIVE_IN_PROCESS = ("--live replays each input over DDS from this process to the estimator nodes it started, one "
                   "replay at a time: the inputs are evaluated in this process")


def executor_setting(args: argparse.Namespace) -> executors.ExecutorSetting:
    """Where the inputs run, from --live, --scheduler and --jobs (ValueError for options that do not combine):
    --live in this process (:data:`LIVE_IN_PROCESS` says why), --scheduler on its Dask cluster, --jobs N > 1 in a
    pool of N processes, else in this process."""
    if args.jobs < 1:
        raise ValueError("--jobs must be at least 1")
    if args.live:
        if args.tune or args.jobs > 1:
            raise ValueError("--live runs one replay at a time: it does not combine with --tune or --jobs")
        if args.scheduler is not None:
            raise ValueError(f"--scheduler does not combine with --live: {LIVE_IN_PROCESS}")
        return executors.ExecutorSetting.in_process(LIVE_IN_PROCESS)
    if args.scheduler is not None:
        if args.jobs > 1:
            raise ValueError("--scheduler runs the inputs on a Dask cluster's workers: it does not combine with "
                             "--jobs (the cluster's workers are the parallelism) or --live")
        setting = executors.ExecutorSetting.dask(args.scheduler)  # a bad address: ValueError
        try:
            executors.require_dask()
        except ev.EvalError as exc:
            raise ValueError(str(exc)) from exc
        return setting
    return executors.ExecutorSetting.pool(args.jobs) if args.jobs > 1 else executors.ExecutorSetting.in_process()


def runner(args: argparse.Namespace) -> AbstractContextManager[Runner | None]:
    """The runner of --live: the evaluator's :class:`~riann_ros.evaluation.live.LiveRunner` over the ROS layer's
    :class:`~riann_ros.ros.dds_replay.DdsReplay` (ev.EvalError without ROS, or for a topic ROS does not take), its
    warnings and (unless -q) its progress on stderr; else none (each input's own in-process runs)."""
    if not args.live:
        return nullcontext()
    try:
        from riann_ros.ros.dds_replay import DdsReplay
    except ImportError as exc:
        raise ev.EvalError(f"--live needs rclpy and the ROS message packages: {exc}") from exc
    topics = args.live_topics.split(",") if args.live_topics else None
    try:
        replay = DdsReplay(speed=args.speed, input_topic=args.live_input, topics=topics, use_mag=args.use_mag,
                           mag_topic=args.live_mag, warn=lambda text: err(f"warning: {text}"))
    except ReplayError as exc:
        raise ev.EvalError(f"--live: {exc}") from exc
    return LiveRunner(replay, note=None if args.quiet else err)
