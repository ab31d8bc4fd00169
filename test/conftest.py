"""Shared fixtures: DDS isolation, BROAD access, starting node executables."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from riann_ros.datasets.broad import broad_files, find_broad_dir, read_broad  # (no ROS: the DDS settings below
from riann_ros.recording import Recording  # are read when a test starts rclpy or a node)

# DDS traffic stays on this machine and in domains of this test run's own. The run's base domain is ROS_DOMAIN_ID when
# it is set (the Makefile passes on only a value you set), else one picked from the controlling process's pid, so that
# concurrent runs (CI, other developers) differ: 100, 104, ..., 196. With pytest-xdist (make test, make check) every
# worker runs its tests one after another in a domain of its own, the base plus the worker's number (gw0: the base,
# gw1: the base + 1, ...). The controlling process hands its base to the workers in RIANN_TEST_DOMAIN_BASE.
DOMAIN_MAX = 232  # the largest ID Fast DDS's port mapping allows (7400 + 250 × ID + offsets below 65536)


def dds_domain(env: dict[str, str], pid: int, ppid: int) -> tuple[int, int]:
    """(the run's base domain, this process's domain) for the environment ``env`` of a pytest process."""
    worker = env.get("PYTEST_XDIST_WORKER", "")
    n = int(worker[2:] or 0) if worker.startswith("gw") else 0
    given = env.get("RIANN_TEST_DOMAIN_BASE") or env.get("ROS_DOMAIN_ID", "").strip()
    if given:
        try:
            base = int(given)
        except ValueError:
            raise ValueError(f"ROS_DOMAIN_ID={given!r} is not a domain ID (an integer 0 … {DOMAIN_MAX})") from None
        count = int(env.get("PYTEST_XDIST_WORKER_COUNT") or 1)
        if not 0 <= base <= DOMAIN_MAX + 1 - count:
            raise ValueError(f"ROS_DOMAIN_ID={base}: the tests need domains {base} … {base + count - 1} (one per "
                             f"pytest-xdist worker), the largest ID is {DOMAIN_MAX}")
        return base, base + n
    base = 100 + ((ppid if worker else pid) % 25) * 4
    return base, base + n % 4


os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
_base, _domain = dds_domain(dict(os.environ), os.getpid(), os.getppid())
os.environ["RIANN_TEST_DOMAIN_BASE"] = str(_base)
os.environ["ROS_DOMAIN_ID"] = str(_domain)
os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent


@pytest.fixture(scope="session")
def broad_dir() -> Path:
    d = find_broad_dir()
    if d is None:
        pytest.skip("BROAD trials not found (set RIANN_BROAD_DIR or place them in ../shared/datasets/broad)")
    return d


@pytest.fixture(scope="session")
def broad_trial(broad_dir: Path):
    """Load a BROAD trial by its two-digit number (cached)."""
    cache: dict[str, Recording] = {}

    def load(number: str) -> Recording:
        if number not in cache:
            files = [p for p in broad_files(broad_dir) if p.name.startswith(number + "_")]
            if not files:
                pytest.skip(f"BROAD trial {number} not in {broad_dir}")
            cache[number] = read_broad(files[0])
        return cache[number]

    return load


def executable(name: str) -> Path:
    """A console script installed beside the running Python (the venv's bin)."""
    p = BIN / name
    if not p.exists():
        found = shutil.which(name)
        if found is None:
            pytest.fail(f"{name} is not installed (run make setup)")
        p = Path(found)
    return p


class NodeProcess:
    """A node executable running as a child process; its output is kept for assertions."""

    def __init__(self, cmd: list[str], log: Path) -> None:
        self.log = log
        self._fh = log.open("w")
        self.proc = subprocess.Popen(cmd, stdout=self._fh, stderr=subprocess.STDOUT, env=os.environ.copy())

    def output(self) -> str:
        self._fh.flush()
        return self.log.read_text()

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(2)  # SIGINT, like Ctrl-C
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._fh.close()
        return self.proc.returncode


@pytest.fixture
def start_node(tmp_path: Path) -> Iterator:
    procs: list[NodeProcess] = []

    def start(name: str, *ros_args: str, cmd: list[str] | None = None) -> NodeProcess:
        full = (cmd or [str(executable(name))]) + (["--ros-args", *ros_args] if ros_args else [])
        p = NodeProcess(full, tmp_path / f"{name}-{len(procs)}.log")
        procs.append(p)
        return p

    yield start
    for p in procs:
        p.stop()


def wait_for(cond, timeout: float, what: str, period: float = 0.01) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return
        time.sleep(period)
    raise AssertionError(f"timed out after {timeout} s waiting for {what}")


# How long a match seen on this side waits for the other side to see it too. DDS discovery is two-way: our
# writer lists the node's reader as matched when *we* have processed its announcement, but the node's reader
# accepts our samples only once *it* has processed ours, and a loaded machine can lag there by a second.
# Samples sent in between are lost to a volatile reader (a CI run lost the first of 150 that way).
MATCH_GRACE_S = 1.0


def wait_matched(writers, collectors, what: str, n_subs: int = 1, timeout: float = 40.0) -> None:
    """Wait until each of our ``writers`` has ``n_subs`` matched readers and each collector a matched writer,
    then :data:`MATCH_GRACE_S` more for the node side of the same matches."""
    wait_for(lambda: all(w.get_subscription_count() >= n_subs for w in writers)
             and all(c.sub.get_publisher_count() > 0 for c in collectors), timeout, what)
    time.sleep(MATCH_GRACE_S)


class RosHarness:
    """The test side of the ROS graph: one rclpy node spun in a background thread."""

    def __init__(self) -> None:
        import threading

        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node("riann_test_harness", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self.executor.spin, daemon=True)
        self._thread.start()

    def qos(self, reliable: bool = True, depth: int = 10000):
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

        return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth, durability=DurabilityPolicy.VOLATILE,
                          reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT)

    def publisher(self, msg_type, topic: str, reliable: bool = True, depth: int = 10000):
        return self.node.create_publisher(msg_type, topic, self.qos(reliable, depth))

    def collect(self, msg_type, topic: str, reliable: bool = True) -> Collector:
        c = Collector()
        c.sub = self.node.create_subscription(msg_type, topic, c.messages.append, self.qos(reliable))
        return c

    def destroy(self, *entities) -> None:
        for e in entities:
            if hasattr(e, "sub"):
                self.node.destroy_subscription(e.sub)
            else:
                self.node.destroy_publisher(e)

    def shutdown(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self.context.try_shutdown()


class Collector:
    def __init__(self) -> None:
        self.messages: list = []
        self.sub = None


@pytest.fixture(scope="session")
def ros() -> Iterator[RosHarness]:
    h = RosHarness()
    yield h
    h.shutdown()


def gate_dts(rec: Recording):
    """Per-sample dt of a recording as the input gate gives it with ``nominal_rate`` = the recording's rate."""
    from riann_ros import stamps

    return stamps.dts(rec.stamps_ns, 1.0 / rec.rate_hz)


def rmse(rec: Recording, q) -> float:
    """Inclination RMSE (°) of estimates ``q`` on ``rec`` over its score mask (the evaluator's scoring)."""
    from riann_ros.evaluation import score

    return score(rec, q).rmse_deg


@pytest.fixture(scope="module")
def three(tmp_path_factory) -> list[Path]:
    """Three short synthetic bags with different gyro biases and accelerometer noise (the plot and --compare tests)."""
    import numpy as np
    from test_evaluation import synthetic

    from riann_ros import bagio

    d = tmp_path_factory.mktemp("three")
    out = []
    for i in range(3):
        rec = synthetic(name=f"s{i}", t0_ns=1_700_000_000_000_000_000, gyr_bias=(0.01 * i, -0.02, 0.005))
        rec.acc = rec.acc + np.random.default_rng(i).normal(0, 0.1, rec.acc.shape)
        out.append(bagio.write_recording(d / f"s{i}.mcap", rec))
    return out
