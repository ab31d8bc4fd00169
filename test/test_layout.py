"""The core stays ROS-free: it imports and runs with rclpy and the message packages unavailable."""

from __future__ import annotations

import subprocess
import sys

CORE = ["quaternion", "metrics", "recording", "stream", "resample", "evaluation", "report", "bagio",
        "estimators", "estimators.riann", "estimators.madgwick", "estimators.mahony", "estimators.vqf_estimator",
        "datasets", "datasets.broad", "datasets.euroc", "datasets.csvfile", "datasets.synthetic"]


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
