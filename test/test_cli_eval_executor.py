"""riann-bag-eval's executor options (riann_ros.cli.eval_executor): the executor is an explicit setting decided from
--live, --scheduler and --jobs; --live runs in this process and says why."""

from __future__ import annotations

import pytest

from conftest import ROOT
from riann_ros.cli.eval_executor import LIVE_IN_PROCESS, executor_setting
from riann_ros.cli.evaluate import main
from riann_ros.cli.evaluate_parser import build_parser
from riann_ros.evaluation.executors import ExecutorKind, ExecutorSetting

BAG = str(ROOT / "bags" / "synthetic_rotation_100hz.mcap")


def setting(*options: str) -> ExecutorSetting:
    return executor_setting(build_parser().parse_args([BAG, *options]))


def test_each_option_gives_its_executor():
    assert setting() == ExecutorSetting(ExecutorKind.IN_PROCESS)
    assert setting("--jobs", "1") == ExecutorSetting.in_process()
    assert setting("--jobs", "3") == ExecutorSetting(ExecutorKind.POOL, jobs=3)
    pytest.importorskip("distributed")
    assert setting("--scheduler", "local:2") == ExecutorSetting(ExecutorKind.DASK, scheduler="local:2")


def test_live_runs_in_process_and_says_why():
    s = setting("--live")
    assert s.kind is ExecutorKind.IN_PROCESS and s.why == LIVE_IN_PROCESS
    assert "--live replays each input over DDS from this process" in s.why


@pytest.mark.parametrize("options, refusal", [
    (["--live", "--jobs", "2"], "--live runs one replay at a time: it does not combine with --tune or --jobs"),
    (["--live", "--tune", "madgwick"], "--live runs one replay at a time"),
    (["--live", "--scheduler", "local:2"], f"--scheduler does not combine with --live: {LIVE_IN_PROCESS}"),
    (["--jobs", "0"], "--jobs must be at least 1"),
])
def test_options_that_do_not_combine_are_refused_before_any_work(options, refusal, capsys):
    with pytest.raises(ValueError, match="^" + refusal.replace("(", r"\(")):
        setting(*options)
    assert main([BAG, *options, "-q"]) == 2
    assert refusal in capsys.readouterr().err
