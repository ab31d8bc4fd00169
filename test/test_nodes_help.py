"""``<node> --help`` and ``-h`` for every node executable: usage, ROS arguments, topics and every parameter (name,
default, range, description, from the specs the node declares), exit status 0, and no ROS started (the process
exits on its own, before rclpy is initialised: no start-up line, nothing on stderr)."""

from __future__ import annotations

import re
import subprocess

import pytest

from conftest import ROOT, executable
from riann_ros.estimators import estimator_class
from riann_ros.nodes.parameters import NODE_PARAMS
from riann_ros.nodes.usage import _default, help_requested

# the node executables setup.py installs (console scripts named *_node)
NODES = re.findall(r'"(\w+_node) = riann_ros\.nodes\.\w+:main"', (ROOT / "setup.py").read_text())


def test_setup_py_installs_the_five_nodes():
    assert sorted(NODES) == ["consensus_node", "madgwick_node", "mahony_node", "riann_node", "vqf_node"]


def test_help_is_asked_outside_the_ros_arguments_only():
    assert help_requested(["riann_node", "--help"]) and help_requested(["riann_node", "-h", "--ros-args", "-p", "a:=1"])
    assert help_requested(["n", "--ros-args", "-p", "a:=1", "--", "-h"])
    assert not help_requested(["n", "--ros-args", "--help"]) and not help_requested(["n"])


def check_help(node: str, text: str) -> None:
    """``text`` is ``node``'s help: usage, ROS arguments, topics, every parameter with default and description."""
    assert text.startswith(f"usage: {node} [-h] [--ros-args"), text[:200]
    flat = " ".join(text.split())
    for part in ("-r FROM:=TO", "-p NAME:=VALUE", "--params-file FILE", "imu/data_raw", "/diagnostics", "~/reset",
                 "~/restart"):
        assert part in text, part
    specs = (*NODE_PARAMS, *estimator_class(node.removesuffix("_node")).PARAMS)
    for s in specs:
        assert f"\n  {s.name} = {_default(s)}" in text, s.name
        assert " ".join(s.description.split()) in flat, s.name


@pytest.mark.parametrize("node", NODES)
@pytest.mark.parametrize("flag", ["--help", "-h"])
def test_node_help_prints_usage_and_parameters_and_exits(node: str, flag: str) -> None:
    r = subprocess.run([str(executable(node)), flag], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and r.stderr == "", r.stderr
    check_help(node, r.stdout)
    assert "estimator on '" not in r.stdout  # the node's start-up line: it never started
