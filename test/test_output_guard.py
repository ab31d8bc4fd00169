"""Every estimator's outputs against a recording of them (``bench/output_guard.py record DIR``, from the version a
change must not alter): offline through the evaluator's pipeline within 1e-6, and riann_node over DDS within 1e-4
(the node runs sample by sample, the recording in blocks: float32 round-off of the network's state).

The recording is derived from BROAD and is not in the repository: set ``RIANN_OUTPUT_GUARD`` to its folder (and
``RIANN_BROAD_DIR`` if BROAD is elsewhere); without them these tests skip, except the one that checks the guard still
taps the evaluator (a bundled bag). ``bench/output_guard.py check DIR`` runs
the whole comparison (every trial and condition, about 20 min of CPU).
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from conftest import ROOT

sys.path.insert(0, str(ROOT / "bench"))

TRIAL = "07"  # fast rotation: every stage busy
CONDITIONS = ("none", "jitter:10/20/30ms", "latency:0-10ms", "fifo:20ms", "dropout:0.1-0.6s@10s", "bias:3,3,0")


@pytest.fixture(scope="module")
def guard_dir() -> Path:
    d = os.environ.get("RIANN_OUTPUT_GUARD")
    if not d or not Path(d).is_dir():
        pytest.skip("no recorded outputs (set RIANN_OUTPUT_GUARD to a bench/output_guard.py record folder)")
    return Path(d)


def _trial_file(broad_dir: Path, number: str) -> Path:
    from riann_ros.datasets.broad import broad_files

    return next(p for p in broad_files(broad_dir) if p.name.startswith(number + "_"))


@pytest.mark.broad
@pytest.mark.slow
@pytest.mark.parametrize("mode", ["6d", "9d"])
def test_offline_outputs_equal_the_recording(guard_dir, broad_dir, mode):
    import output_guard

    path = guard_dir / f"{TRIAL}-{mode}.npz"
    if not path.is_file():
        pytest.skip(f"{path} not recorded")
    ref = np.load(path)
    got = output_guard.outputs(str(_trial_file(broad_dir, TRIAL)), output_guard.MODES[mode], CONDITIONS, "25,100")
    assert set(got) <= set(ref.files)
    for key, q in got.items():
        diff = np.abs(q.astype(np.float64) - ref[key].astype(np.float64))
        assert np.array_equal(np.isnan(q), np.isnan(ref[key])), key
        assert np.nanmax(diff) < 1e-6, (key, float(np.nanmax(diff)))


@pytest.mark.broad
@pytest.mark.slow
@pytest.mark.ros
def test_node_outputs_equal_the_recording(guard_dir, broad_trial, ros, start_node):
    from geometry_msgs.msg import QuaternionStamped
    from sensor_msgs.msg import Imu

    from conftest import wait_matched
    from helpers_ros import imu_msg, publish_paced, quats

    number = "33"
    path = guard_dir / f"{number}-6d.npz"
    if not path.is_file():
        pytest.skip(f"{path} not recorded")
    ref = np.load(path)["as-recorded|none|native|riann"].astype(np.float64)
    rec = broad_trial(number)
    node = start_node("riann_node", "-p", "input_qos:=reliable", "-p", "input_depth:=1000",
                      "-p", f"nominal_rate:={rec.rate_hz}")
    pub = ros.publisher(Imu, "imu/data_raw", reliable=True)
    att = ros.collect(QuaternionStamped, "imu/attitude")
    wait_matched([pub], [att], f"node to connect (log: {node.output()})")
    stamps = rec.stamps_ns + 1_700_000_000_000_000_000
    msgs = [imu_msg(s, a, g) for s, a, g in zip(stamps, rec.acc, rec.gyr, strict=True)]
    publish_paced(pub, msgs, att.messages, len(msgs))
    time.sleep(0.2)
    q = quats(att.messages)
    assert q.shape == ref.shape
    assert np.abs(q - ref).max() < 1e-4
    ros.destroy(pub, att)


def test_the_guard_taps_every_run_of_the_evaluator():
    """The guard reads RIANN's outputs at the evaluator's scenario run (no recording needed): a rename there must fail
    here, not in an hours-long check."""
    import output_guard

    from riann_ros.bagio import read_recording

    bag = ROOT / "bags" / "synthetic_rotation_100hz.mcap"
    got = output_guard.outputs(str(bag), "false", conditions=("none", "bias:3,3,0"), rates="50", estimators="riann")
    runs = {f"{s}|{c}|native" for s in ("as-recorded", "realistic") for c in ("none", "bias:3,3,0")} | {
        "as-recorded|none|50"}
    assert set(got) == {f"{r}|riann{k}" for r in runs for k in ("", "|sigma")}
    n = len(read_recording(bag))
    assert len(got["as-recorded|none|native|riann"]) == n
    assert len(got["as-recorded|none|native|riann|sigma"]) == n  # σ of inclination and heading (and its state)
    for key, q in got.items():
        if not key.endswith("|sigma"):
            assert np.all(np.isfinite(q)) and np.allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-5)
