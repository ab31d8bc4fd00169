"""The launch files run: their node actions, turned into the command lines launch_ros runs (launch_ros is not
installable here: test/helpers_launch.py), start the real executables, checked over DDS.

* ``riann.launch.py namespace:=robot1 mag_topic:=/robot1/magnetometer``: the node lives in /robot1, reads the
  remapped magnetometer and publishes under /robot1;
* ``side_by_side.launch.py`` with no arguments keeps what the parameter files say (a nominal_rate of 250 in
  riann.yaml is not replaced by a launch default); with ``namespace`` and ``mag_topic`` all five nodes follow.
"""

from __future__ import annotations

import shutil
import time

import helpers_launch as hl
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import QuaternionStamped
from sensor_msgs.msg import Imu, MagneticField
from test_nodes_node_base import mag_msg, motion

from conftest import BIN, ROOT, wait_for, wait_matched
from helpers_ros import imu_msg

pytestmark = pytest.mark.ros


@pytest.fixture
def share(tmp_path, monkeypatch):
    """A package share with the repository's config files (as colcon installs them) and the stand-in launch
    modules."""
    d = tmp_path / "share" / "riann_ros"
    shutil.copytree(ROOT / "config", d / "config")
    hl.install_stand_ins(monkeypatch, d)
    return d


def run_launch(start_node, tmp_path, file: str, **given: str):
    """Start the nodes of launch file ``file`` with the launch arguments ``given`` (the others at their default)."""
    _, entities = hl.load(file)
    context = {**hl.arguments(entities), **given}
    procs = {}
    for node in hl.nodes(entities, context):
        cmd = hl.node_command(node, BIN, tmp_path)
        procs[node.kwargs["name"]] = start_node(node.kwargs["executable"], cmd=cmd)
    return procs


def send(pub_imu, pub_mag, n: int, collectors) -> None:
    stamps, acc, gyr, mag = motion(n)
    for i in range(n):
        if i % 4 == 0:
            pub_mag.publish(mag_msg(stamps[i], mag[i]))
        while i - min(len(c.messages) for c in collectors) >= 50:
            time.sleep(0.0002)
        pub_imu.publish(imu_msg(stamps[i], acc[i], gyr[i]))
        time.sleep(0.001)
    wait_for(lambda: min(len(c.messages) for c in collectors) >= n, 30, "outputs")


def test_riann_launch_namespace_and_mag_topic(ros, start_node, share, tmp_path):
    nodes = run_launch(start_node, tmp_path, "riann.launch.py", namespace="robot1",
                       mag_topic="/robot1/magnetometer", nominal_rate="400")
    node = nodes["riann_node"]
    wait_for(lambda: "parameters:" in node.output(), 60, f"riann_node to start ({node.output()})")
    log = node.output()
    assert "on '/robot1/imu/data_raw' -> '/robot1/imu/attitude', '/robot1/imu/data'" in log, log
    assert "magnetometer on '/robot1/magnetometer'" in log and "nominal_rate=400.0" in log
    pub_imu = ros.publisher(Imu, "/robot1/imu/data_raw")
    pub_mag = ros.publisher(MagneticField, "/robot1/magnetometer")
    att = ros.collect(QuaternionStamped, "/robot1/imu/attitude")
    diag = ros.collect(DiagnosticArray, "/diagnostics")
    wait_matched([pub_imu, pub_mag], [att], f"riann_node in /robot1 ({node.output()})")
    send(pub_imu, pub_mag, 400, [att])

    def field_counted(d) -> bool:
        s = d.status[0]
        v = {kv.key: kv.value for kv in s.values}
        return s.name.startswith("riann_node") and int(v["field readings received (total)"]) >= 90
    wait_for(lambda: any(field_counted(d) for d in diag.messages), 10, "the remapped magnetometer in /diagnostics")
    ros.destroy(pub_imu, pub_mag, att, diag)


def test_side_by_side_launch_keeps_the_files_values_and_follows_namespace_and_mag_topic(ros, start_node, share,
                                                                                         tmp_path):
    riann_yaml = share / "config" / "riann.yaml"
    riann_yaml.write_text(riann_yaml.read_text().replace("nominal_rate: 100.0", "nominal_rate: 250.0"))
    nodes = run_launch(start_node, tmp_path, "side_by_side.launch.py", namespace="robot2",
                       mag_topic="/robot2/magnetometer")
    for name, node in nodes.items():
        wait_for(lambda n=node: "parameters:" in n.output(), 90, f"{name} to start ({node.output()})")
    # no launch default over the files: riann.yaml's 250, the others' default 100 (their files have none)
    assert "nominal_rate=250.0" in nodes["riann_node"].output()
    for name in ("madgwick_node", "mahony_node", "vqf_node", "consensus_node"):
        assert "nominal_rate=100.0" in nodes[name].output(), name
        assert "magnetometer on '/robot2/magnetometer'" in nodes[name].output()
    pub_imu = ros.publisher(Imu, "/robot2/imu/data_raw")
    pub_mag = ros.publisher(MagneticField, "/robot2/magnetometer")
    att = [ros.collect(QuaternionStamped, f"/robot2/{t}") for t in
           ("imu/attitude", "imu/madgwick/attitude", "imu/mahony/attitude", "imu/vqf/attitude",
            "imu/consensus/attitude")]
    wait_matched([pub_imu, pub_mag], att, "the five nodes in /robot2", n_subs=5)
    send(pub_imu, pub_mag, 200, att)
    ros.destroy(pub_imu, pub_mag, *att)
