"""`ros2 run riann_ros riann_node` = colcon build, source install/setup.bash, run the installed file."""

from __future__ import annotations

import os
import shutil
import subprocess

import pytest
from geometry_msgs.msg import QuaternionStamped
from sensor_msgs.msg import Imu
from test_nodes_help import NODES, check_help

from conftest import BIN, ROOT, wait_for, wait_matched
from helpers_ros import imu_msg

pytestmark = [pytest.mark.ros, pytest.mark.slow]

PACKAGE_FILES = ["package.xml", "setup.py", "setup.cfg", "resource", "config", "launch", "riann_ros"]


@pytest.fixture(scope="module")
def workspace(tmp_path_factory):
    if not (BIN / "colcon").exists():
        pytest.fail("colcon is not installed in the environment (requirements-dev.txt)")
    ws = tmp_path_factory.mktemp("ws")
    src = ws / "src" / "riann_ros"
    src.mkdir(parents=True)
    for name in PACKAGE_FILES:
        p = ROOT / name
        if p.is_dir():
            shutil.copytree(p, src / name, ignore=shutil.ignore_patterns("__pycache__"))
        elif p.exists():
            shutil.copy2(p, src / name)
    env = dict(os.environ, PATH=f"{BIN}{os.pathsep}{os.environ['PATH']}")
    r = subprocess.run([str(BIN / "colcon"), "build"], cwd=ws, env=env, capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    return ws


def test_colcon_build_installs_the_executables(workspace):
    lib = workspace / "install" / "riann_ros" / "lib" / "riann_ros"
    for exe in ("riann_node", "madgwick_node", "mahony_node", "vqf_node", "consensus_node", "riann-bag-convert",
                "riann-bag-eval", "riann-topic"):
        assert (lib / exe).is_file() and os.access(lib / exe, os.X_OK), exe
    share = workspace / "install" / "riann_ros" / "share" / "riann_ros"
    assert (share / "package.xml").is_file() and (share / "config" / "riann.yaml").is_file()
    assert list((workspace / "install" / "riann_ros" / "lib").glob("python3*/site-packages/riann_ros/stream.py"))


def test_installed_riann_node_runs_after_sourcing_setup_bash(workspace, ros, start_node):
    exe = workspace / "install" / "riann_ros" / "lib" / "riann_ros" / "riann_node"
    cmd = ["bash", "-c", f"source {workspace}/install/setup.bash && exec {exe} \"$@\"", "riann_node"]
    params = workspace / "install" / "riann_ros" / "share" / "riann_ros" / "config" / "riann.yaml"
    node = start_node("riann_node", "--params-file", str(params), "-p", "input_qos:=reliable", cmd=cmd)
    pub = ros.publisher(Imu, "imu/data_raw")
    att = ros.collect(QuaternionStamped, "imu/attitude")
    wait_matched([pub], [att], f"the installed node to connect (log: {node.output()})")
    for i in range(20):
        pub.publish(imu_msg(1_000_000_000 + i * 5_000_000, (0.0, 0.0, 9.81), (0.0, 0.0, 0.0)))
    wait_for(lambda: len(att.messages) >= 20, 10, "outputs from the installed node")
    assert "riann estimator on '/imu/data_raw'" in node.output()
    ros.destroy(pub, att)


def test_installed_nodes_print_their_help_and_exit(workspace):
    """`ros2 run riann_ros <node> --help`: the colcon-installed executables print their help and exit 0."""
    lib = workspace / "install" / "riann_ros" / "lib" / "riann_ros"
    for node in NODES:
        cmd = f"source {workspace}/install/setup.bash && exec {lib / node} --help"
        r = subprocess.run(["bash", "-c", cmd], capture_output=True, text=True, timeout=60)
        assert r.returncode == 0, r.stderr
        check_help(node, r.stdout)
