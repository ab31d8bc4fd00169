"""``riann-bag-eval --live`` under faults, over real DDS (each test in this pytest process's own ROS_DOMAIN_ID with
ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, set by conftest.py): a topic without its node on the other side stops the
run within 10 s naming it, with no result files; another publisher on a topic of the run is named in a warning;
progress per input and scenario on stderr; the bag's magnetometer replayed to a node of one's own
(``--live-topics`` with ``--live-mag``), which then runs 9D."""

from __future__ import annotations

import json
import time

import pytest
from test_cli_evaluate import magnetometer_bag
from test_evaluation import synthetic

from riann_ros import bagio
from riann_ros.cli.evaluate import main
from riann_ros.ros.started_nodes import LIVE_INPUT_TOPIC

pytest.importorskip("rclpy")
from sensor_msgs.msg import Imu

RESULT_FILES = ("results.csv", "results.json", "report.md")


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    rec = synthetic(name="short", rest_s=1.0, move_s=2.0, t0_ns=1_700_000_000_000_000_000)
    return bagio.write_recording(tmp_path_factory.mktemp("live") / "short.mcap", rec)


def _lines(text: str) -> list[str]:
    return [ln for ln in text.splitlines() if ln.strip()]


@pytest.mark.ros
def test_a_live_input_no_node_reads_stops_the_run_within_10_s_naming_the_topics(bag, tmp_path, capsys):
    out = tmp_path / "out"
    t0 = time.monotonic()
    rc = main([str(bag), "-e", "madgwick", "-s", "as-recorded", "--live", "--live-input", "/riann_test/nowhere",
               "--live-topics", "/riann_test/nothing", "--out", str(out), "-q"])
    took = time.monotonic() - t0
    err = capsys.readouterr().err
    assert rc == 1 and took < 10.0, (rc, took, err)
    (line,) = _lines(err)
    assert "no node subscribes to /riann_test/nowhere" in line and "no node publishes /riann_test/nothing" in line
    assert "Traceback" not in err
    assert not any((out / f).exists() for f in RESULT_FILES)


@pytest.mark.ros
def test_an_attitude_topic_nothing_publishes_is_named_alone(bag, tmp_path, ros, capsys):
    reader = ros.collect(Imu, "/riann_test/read_in")  # the input has a reader: only the output is missing
    try:
        rc = main([str(bag), "-e", "madgwick", "-s", "as-recorded", "--live", "--live-input", "/riann_test/read_in",
                   "--live-topics", "/riann_test/no_attitude", "--out", str(tmp_path / "out"), "-q"])
    finally:
        ros.destroy(reader)
    err = capsys.readouterr().err
    (line,) = _lines(err)
    assert rc == 1 and "no node publishes /riann_test/no_attitude" in line and "read_in" not in line, err
    assert not (tmp_path / "out" / "results.csv").exists()


@pytest.mark.ros
@pytest.mark.slow
def test_another_publisher_on_the_input_is_named_and_each_replay_shows_progress(bag, tmp_path, ros, capsys):
    intruder = ros.publisher(Imu, LIVE_INPUT_TOPIC)  # another node publishing on the run's input (it stays silent)
    try:
        rc = main([str(bag), "-e", "madgwick", "-s", "as-recorded,realistic", "--live", "--speed", "0",
                   "--no-plots", "--out", str(tmp_path / "out")])
    finally:
        ros.destroy(intruder)
    err = capsys.readouterr().err
    assert rc == 0, err
    warnings = [ln for ln in _lines(err) if "warning:" in ln and LIVE_INPUT_TOPIC in ln]
    assert len(warnings) == 1 and "/riann_test_harness" in warnings[0], err
    for scenario in ("as-recorded", "realistic"):
        assert f"live: short {scenario}: replaying to 1 node(s)" in err
        done = [ln for ln in _lines(err) if f"live: short {scenario}: " in ln and " published, received " in ln]
        assert len(done) == 1 and done[0].rstrip().endswith(" s"), err


@pytest.mark.ros
@pytest.mark.slow
def test_the_bags_field_is_replayed_to_a_node_of_ones_own_which_runs_9d(tmp_path, start_node, capsys):
    bag = magnetometer_bag(tmp_path, "mag_own", 1)
    node = start_node("vqf_node", "-r", "imu/data_raw:=/riann_test/own/imu", "-r", "imu/mag:=/riann_test/own/mag",
                      "-r", "imu/vqf/attitude:=/riann_test/own/attitude", "-p", "nominal_rate:=100.0",
                      "-p", "input_qos:=reliable", "-p", "input_depth:=1000")
    args = [str(bag), "-e", "vqf", "-s", "as-recorded", "--live", "--speed", "0", "--no-plots", "-q",
            "--live-input", "/riann_test/own/imu", "--live-topics", "/riann_test/own/attitude"]
    assert main([*args, "--live-mag", "/riann_test/own/mag", "--out", str(tmp_path / "nine")]) == 0, node.output()
    assert main([*args, "--use-mag", "false", "--out", str(tmp_path / "six")]) == 0, node.output()
    capsys.readouterr()
    (nine,) = json.loads((tmp_path / "nine" / "results.json").read_text())["results"]
    (six,) = json.loads((tmp_path / "six" / "results.json").read_text())["results"]
    assert nine["sensors"] == "9D" and nine["heading_rmse_deg"] is not None, nine
    assert six["sensors"] == "6D", six
