"""riann-topic (list, echo, hz) as a user runs it, against a running madgwick_node over real DDS."""

from __future__ import annotations

import re
import subprocess
import sys
import threading
import time

import pytest
import yaml
from sensor_msgs.msg import Imu

from conftest import executable, wait_for, wait_matched
from helpers_ros import imu_msg
from riann_ros.cli.topic import RateStats, plain

RATE = 100.0


def topic_cli(*args: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
    return subprocess.run([str(executable("riann-topic")), *args], capture_output=True, text=True, timeout=timeout)


class Feeder:
    """Publishes a level IMU at RATE (stamps exactly 1/RATE apart) from a thread until stopped."""

    def __init__(self, pub) -> None:
        self.pub = pub
        self.sent = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        t0 = time.monotonic()
        while not self._stop.is_set():
            self.pub.publish(imu_msg(1_000_000_000 + round(self.sent * 1e9 / RATE), (0.1, -0.2, 9.8), (0.0, 0.0, 0.01)))
            self.sent += 1
            time.sleep(max(0.0, t0 + self.sent / RATE - time.monotonic()))

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(5)


@pytest.fixture
def running(ros, start_node):
    node = start_node("madgwick_node", "-p", "publish_rpy:=true", "-p", "input_qos:=reliable",
                      "-p", "diagnostics_period:=0.5")
    pub = ros.publisher(Imu, "imu/data_raw")
    wait_for(lambda: pub.get_subscription_count() > 0, 30, f"madgwick_node ({node.output()})")
    wait_matched([pub], [], "madgwick_node")
    feeder = Feeder(pub)
    yield node
    feeder.stop()
    ros.destroy(pub)


def echo_one(topic: str) -> dict:
    out = topic_cli("echo", topic, "-n", "1")
    assert out.returncode == 0, out.stderr
    (doc,) = [d for d in yaml.safe_load_all(out.stdout) if d is not None]
    return doc


@pytest.mark.ros
def test_echo_prints_each_message_type_as_yaml(running):
    out = topic_cli("echo", "imu/madgwick/attitude", "-n", "3")
    assert out.returncode == 0, out.stderr
    docs = [d for d in yaml.safe_load_all(out.stdout) if d is not None]
    assert len(docs) == 3
    for d in docs:
        assert d["header"]["frame_id"] == "odom" and d["header"]["stamp"]["sec"] >= 1
        q = d["quaternion"]
        assert abs(q["w"] ** 2 + q["x"] ** 2 + q["y"] ** 2 + q["z"] ** 2 - 1.0) < 1e-6
    imu = echo_one("/imu/madgwick/data")
    assert imu["header"]["frame_id"] == "imu_link" and len(imu["orientation_covariance"]) == 9
    assert imu["linear_acceleration"] == {"x": 0.1, "y": -0.2, "z": 9.8}
    rpy = echo_one("imu/madgwick/rpy")
    assert set(rpy["vector"]) == {"x", "y", "z"} and abs(rpy["vector"]["x"]) < 10.0
    diag = echo_one("/diagnostics")
    (status,) = diag["status"]
    assert status["name"] == "madgwick_node: madgwick attitude estimator"
    values = {kv["key"]: kv["value"] for kv in status["values"]}
    assert float(values["input rate (Hz)"]) > 0.0


@pytest.mark.ros
def test_hz_reports_the_rate_of_arrivals_and_of_header_stamps(running):
    out = topic_cli("hz", "imu/madgwick/attitude", "--duration", "4")
    assert out.returncode == 0, out.stderr
    assert "subscribed to /imu/madgwick/attitude [geometry_msgs/msg/QuaternionStamped]" in out.stdout
    arrivals = [float(x) for x in re.findall(r"^average rate: ([\d.]+) Hz", out.stdout, re.M)]
    stamps = [float(x) for x in re.findall(r"^header stamps: ([\d.]+) Hz", out.stdout, re.M)]
    assert len(arrivals) >= 3 and len(stamps) >= 3, out.stdout
    assert 0.6 * RATE < arrivals[-1] < 1.4 * RATE, out.stdout  # wall-clock arrivals on a shared machine
    assert stamps[-1] == pytest.approx(RATE, rel=1e-3), out.stdout  # the stamps are exactly 10 ms apart
    n = int(re.search(r"^(\d+) messages in", out.stdout, re.M).group(1))
    assert 0.6 * 4 * RATE < n < 1.4 * 4 * RATE


@pytest.mark.ros
def test_list_and_errors(running):
    want = ("/imu/madgwick/attitude [geometry_msgs/msg/QuaternionStamped]", "/imu/madgwick/rpy "
            "[geometry_msgs/msg/Vector3Stamped]", "/diagnostics [diagnostic_msgs/msg/DiagnosticArray]",
            "/imu/data_raw [sensor_msgs/msg/Imu]")
    wait_for(lambda: all(w in topic_cli("list", "--wait", "3").stdout for w in want), 60,
             "the node's topics in riann-topic list (discovery takes longer on a loaded machine)")
    out = topic_cli("echo", "/no_such_topic", "--timeout", "1")
    assert out.returncode == 1 and "no topic /no_such_topic after 1 s (ROS_DOMAIN_ID=" in out.stderr
    out = topic_cli("echo", "/imu/madgwick/attitude", "--type", "sensor_msgs/msg/Imu", "--timeout", "5")
    assert out.returncode == 1 and "has type geometry_msgs/msg/QuaternionStamped, not sensor_msgs/msg/Imu" in out.stderr
    assert topic_cli("hz").returncode == 2  # usage


def test_message_helpers_without_dds():
    from geometry_msgs.msg import Vector3Stamped

    m = Vector3Stamped()
    m.vector.x = 1.5
    assert plain(m) == {"header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": ""},
                        "vector": {"x": 1.5, "y": 0.0, "z": 0.0}}
    s = RateStats(window=100)
    for i in range(11):
        s.add(i * 0.01, 5.0 + i * 0.005)
    arrivals, stamps = s.report()
    assert arrivals.startswith("average rate: 100.000 Hz") and stamps.startswith("header stamps: 200.000 Hz")


def test_library_prints_on_fd_1_go_to_stderr():
    """Fast DDS prints its log lines (ANSI-coloured) on file descriptor 1 on a busy machine; riann-topic's stdout
    must stay its own (YAML documents to pipe or parse)."""
    code = ("import os\nfrom riann_ros.cli.topic import keep_stdout_clean\nkeep_stdout_clean()\n"
            "os.write(1, b'\\x1b[31mlibrary line\\n')\nprint('header: {}')\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert r.stdout == "header: {}\n" and "library line" in r.stderr
