"""The core stays ROS-free: it imports and runs with rclpy and the message packages unavailable; so do the CLIs,
which import the ROS layer only when a verb that needs it runs (``riann-bag-eval --live``, ``riann-topic``)."""

from __future__ import annotations

import pkgutil
import subprocess
import sys

import riann_ros

# every module but the ROS layer (riann_ros.nodes, riann_ros.ros); the CLIs too
ROS_LAYER = ("riann_ros.nodes", "riann_ros.ros")
CORE = sorted(
    m.name.removeprefix("riann_ros.")
    for m in pkgutil.walk_packages(riann_ros.__path__, "riann_ros.")
    if not any(m.name == r or m.name.startswith(r + ".") for r in ROS_LAYER)
)


def test_core_list_is_complete():
    assert {"stream", "bagio", "evaluation.run", "evaluation.live", "replay", "estimators.riann", "cli.evaluate",
            "cli.topic", "cli.eval_executor"} <= set(CORE)
    assert not any(m.startswith(("nodes", "ros.")) or m == "ros" for m in CORE)


def test_core_imports_without_ros():
    code = (
        "import sys\n"
        "for m in ('rclpy', 'sensor_msgs', 'geometry_msgs', 'std_msgs', 'diagnostic_msgs', 'std_srvs'):\n"
        "    sys.modules[m] = None\n"
        + "".join(f"import riann_ros.{m}\n" for m in CORE)
        + "from riann_ros.estimators import create\n"
        "from riann_ros.stream import EstimatorStream\n"
        "s = EstimatorStream(create('riann'))\n"
        "q, r = s.process(1_000_000_000, (0.0, 0.0, 9.81), (0.0, 0.0, 0.0))\n"
        "assert r.accepted and abs(sum(q * q) - 1) < 1e-9\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
