"""The estimator nodes a DDS replay starts (:mod:`riann_ros.ros.dds_replay`): one ``<name>_node`` process per
:class:`~riann_ros.replay.NodeSpec`, in a namespace of the replay's own, with reliable deep queues and the
sequence's rate as ``nominal_rate``; restarted before each sequence through their ``~/restart`` service."""

from __future__ import annotations

import importlib
import shutil
import signal
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from std_srvs.srv import Trigger

from riann_ros.nodes.node_base import EstimatorNode
from riann_ros.replay import NodeSpec, ReplayError
from riann_ros.ros.services import call_service

LIVE_NS = "/riann_eval"
LIVE_INPUT_TOPIC = f"{LIVE_NS}/imu/data_raw"
LIVE_MAG_TOPIC = f"{LIVE_NS}/imu/mag"


def ros_param(value: Any) -> str:
    """A parameter value as ``-p name:=value`` text."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)  # keeps the decimal point: the nodes declare float parameters
    if isinstance(value, tuple):  # a float array (mag_hard_iron, mag_soft_iron)
        return "[" + ", ".join(repr(float(v)) for v in value) + "]"
    return str(value)


def node_topics(name: str) -> tuple[str, str]:
    """(attitude topic, imu output topic) of the ``<name>_node`` class, to remap them."""
    mod = importlib.import_module(f"riann_ros.nodes.{name}_node")
    for obj in vars(mod).values():
        if isinstance(obj, type) and issubclass(obj, EstimatorNode) and obj.ESTIMATOR == name:
            return obj.ATTITUDE_TOPIC, obj.IMU_TOPIC
    return "imu/attitude", "imu/data"


def node_executable(name: str) -> str:
    exe = Path(sys.executable).parent / f"{name}_node"
    if exe.exists():
        return str(exe)
    found = shutil.which(f"{name}_node")
    if found is None:
        raise ReplayError(f"{name}_node is not installed (run make setup)")
    return found


def output_topic(i: int) -> str:
    """The ``sensor_msgs/Imu`` output of the i-th started node (its orientation and covariance)."""
    return f"{LIVE_NS}/e{i}/imu"


def node_command(i: int, node: NodeSpec, rate: float, input_topic: str, use_mag: str,
                 mag_topic: str = LIVE_MAG_TOPIC) -> list[str]:
    """The command line of the i-th node: its topics remapped into the replay's namespace (its input and field to
    the replay's topics), reliable deep queues."""
    att_topic, imu_topic = node_topics(node.name)
    remaps = {"__node": f"riann_eval_{i}_{node.name}", "imu/data_raw": input_topic, "imu/mag": mag_topic,
              att_topic: f"{LIVE_NS}/e{i}/attitude", imu_topic: output_topic(i)}
    params = {"input_qos": "reliable", "input_depth": 1000, "output_depth": 1000, "nominal_rate": float(rate),
              "use_mag": use_mag, **dict(node.params)}
    return [node_executable(node.name), "--ros-args",
            *(a for k, v in remaps.items() for a in ("-r", f"{k}:={v}")),
            *(a for k, v in params.items() for a in ("-p", f"{k}:={ros_param(v)}"))]


class StartedNodes:
    """The node processes of one set of specs at one rate, each logging into ``log_dir``."""

    def __init__(self, log_dir: Path) -> None:
        self.log_dir = log_dir
        self.procs: list[subprocess.Popen] = []

    def start(self, nodes: Sequence[NodeSpec], rate: float, input_topic: str, use_mag: str,
              mag_topic: str = LIVE_MAG_TOPIC) -> None:
        for i, node in enumerate(nodes):
            with open(self.log_dir / f"node_{i}_{node.name}.log", "w") as log:  # the child keeps its own fd
                cmd = node_command(i, node, rate, input_topic, use_mag, mag_topic)
                self.procs.append(subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT))

    def any_ended(self) -> bool:
        return any(p.poll() is not None for p in self.procs)

    def logs(self) -> str:
        """The end of each node's log, for an error message."""
        return "; ".join(f"{p.name}: {p.read_text()[-300:]}" for p in sorted(self.log_dir.glob("node_*.log")))

    def restart(self, client_node: Any, nodes: Sequence[NodeSpec], timeout: float = 10.0) -> None:
        """Call every started node's ``~/restart`` from ``client_node``: each sequence starts its estimator as freshly
        built, as the offline run does (a stamp gap alone would not: RIANN keeps its gyro-bias estimate across gaps;
        nor would ``~/reset``: it keeps the robot's magnetometer calibration and latency fit)."""
        for i, node in enumerate(nodes):
            client = client_node.create_client(Trigger, f"/riann_eval_{i}_{node.name}/restart")
            try:
                if not client.wait_for_service(timeout_sec=timeout):
                    raise ReplayError(f"{node.name}_node offers no ~/restart service")
                if call_service(client, Trigger.Request(), timeout) is None:
                    raise ReplayError(f"{node.name}_node did not answer ~/restart")
            finally:
                client_node.destroy_client(client)

    def stop(self) -> None:
        for p in self.procs:
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
        for p in self.procs:
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        self.procs = []
