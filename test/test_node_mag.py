"""The magnetometer over real DDS: a 400 Hz IMU with a 100 Hz sensor_msgs/MagneticField on imu/mag.

One output per IMU message, equal to the offline path (the bag reader's pairing + EstimatorStream) within 1e-4;
when the magnetometer stops the node goes on without a gap (heading held by the gyro, 6D in /diagnostics) and
goes back to 9D when the field returns.
"""

from __future__ import annotations

import time

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import QuaternionStamped
from sensor_msgs.msg import Imu, MagneticField

from conftest import wait_for, wait_matched
from helpers_ros import imu_msg, quats, stamp_ns
from riann_ros import quaternion as quat
from riann_ros import stamps as st_ns
from riann_ros.estimators import create
from riann_ros.mag import FIELD_STALE, FIELD_USED, MagConfig, pair_fields
from riann_ros.stream import EstimatorStream, GateConfig

pytestmark = pytest.mark.ros

RATE = 400.0
MAG_EVERY = 4  # 100 Hz
FIELD_ENU = np.array([0.0, 20e-6, -40e-6])  # T, y = magnetic north, a downward vertical component
T0 = 1_700_000_000_000_000_000


def motion(n: int, seed: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Stamps, acc, gyr and the field in the sensor frame of a smooth rotation (tilt and a slow turn)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / RATE
    gyr = np.column_stack([0.4 * np.sin(0.7 * t), 0.3 * np.cos(0.5 * t), 0.5 * np.sin(0.2 * t + 0.3)])
    gyr += rng.normal(0.0, 0.002, gyr.shape)
    q = np.empty((n, 4))
    q[0] = quat.from_rotvec([0.2, -0.1, 0.4])
    steps = quat.from_rotvec(gyr[1:] / RATE)
    for i in range(1, n):
        q[i] = quat.multiply(q[i - 1], steps[i - 1])
    inv = quat.conjugate(q)
    acc = quat.rotate(inv, np.tile([0.0, 0.0, 9.81], (n, 1))) + rng.normal(0.0, 0.05, (n, 3))
    mag = quat.rotate(inv, np.tile(FIELD_ENU, (n, 1))) + rng.normal(0.0, 0.3e-6, (n, 3))
    stamps = T0 + np.round(t * 1e9).astype(np.int64)
    return stamps, acc, gyr, mag


def mag_msg(stamp: int, m) -> MagneticField:
    msg = MagneticField()
    st_ns.set_ns(msg.header.stamp, int(stamp))
    msg.header.frame_id = "imu_link"
    msg.magnetic_field.x, msg.magnetic_field.y, msg.magnetic_field.z = (float(v) for v in m)
    return msg


def send(ros, pub_imu, pub_mag, att, stamps, acc, gyr, mag, mag_until: int, window: int = 50) -> list[int]:
    """IMU messages in order; a field reading every MAG_EVERY samples before ``mag_until``, published two IMU periods
    ahead of its stamp (so it is there when the IMU message of that stamp arrives). Returns the field indices sent."""
    sent = []
    for i in range(len(stamps)):
        j = i + 2
        if j < min(len(stamps), mag_until) and j % MAG_EVERY == 0:
            pub_mag.publish(mag_msg(stamps[j], mag[j]))
            sent.append(j)
        while i - len(att.messages) >= window:
            time.sleep(0.0002)
        pub_imu.publish(imu_msg(stamps[i], acc[i], gyr[i]))
        time.sleep(0.0005)
    return sent


def offline(stamps, acc, gyr, mag, sent: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """The offline estimates and their σ (inclination, heading; rad)."""
    fields = pair_fields(stamps, stamps[sent], mag[sent], MagConfig().timeout_ns)
    stream = EstimatorStream(create("riann"), GateConfig(nominal_rate=RATE))
    q, ok = stream.process_batch(stamps, acc, gyr, fields)
    assert ok.all()
    return q, stream.batch_sigma


def test_400hz_imu_with_100hz_mag_equals_offline_and_survives_the_mag_stopping(ros, start_node):
    node = start_node("riann_node", "-p", "input_qos:=reliable", "-p", f"nominal_rate:={RATE}",
                      "-p", "diagnostics_period:=0.2")
    pub_imu = ros.publisher(Imu, "imu/data_raw")
    pub_mag = ros.publisher(MagneticField, "imu/mag")
    att = ros.collect(QuaternionStamped, "imu/attitude")
    imu_out = ros.collect(Imu, "imu/data")
    diags = ros.collect(DiagnosticArray, "/diagnostics")
    wait_matched([pub_imu, pub_mag], [att, imu_out], f"node to connect (log: {node.output()})")
    n = int(12 * RATE)
    stamps, acc, gyr, mag = motion(n)
    # the magnetometer stops after 6 s (its publisher goes away) and comes back for the last 3 s
    sent = send(ros, pub_imu, pub_mag, att, stamps[: n // 2], acc, gyr, mag, mag_until=n // 2)
    ros.destroy(pub_mag)
    stale_from = len(att.messages)
    sent_b = send(ros, pub_imu, None, att, stamps[n // 2 : 3 * n // 4], acc[n // 2 :], gyr[n // 2 :], None,
                  mag_until=0)
    wait_for(lambda: len(att.messages) >= 3 * n // 4, 20, "outputs while the magnetometer is gone")
    time.sleep(0.5)  # a diagnostics period with the field stale
    states_gone = [kv.value for d in diags.messages for s in d.status for kv in s.values if kv.key == "magnetometer"]
    pub_mag2 = ros.publisher(MagneticField, "imu/mag")
    wait_matched([pub_mag2], [], "the magnetometer to reconnect")
    rest = slice(3 * n // 4, n)
    sent_c = send(ros, pub_imu, pub_mag2, att, stamps[rest], acc[rest], gyr[rest], mag[rest], mag_until=n)
    sent_c = [3 * n // 4 + j for j in sent_c]
    wait_for(lambda: len(att.messages) >= n, 30, f"all outputs ({len(att.messages)} of {n})")
    time.sleep(0.5)
    assert not sent_b
    got = att.messages
    assert [stamp_ns(m) for m in got] == stamps.tolist(), "one output per IMU message, in order, no gap"
    q_off, sigma = offline(stamps, acc, gyr, mag, sent + sent_c)
    q_node = quats(got)
    d = np.minimum(np.abs(q_node - q_off).max(axis=1), np.abs(q_node + q_off).max(axis=1))  # q ≡ −q (w ≈ 0)
    assert d.max() < 1e-4, np.flatnonzero(d > 1e-4)[:10]
    # 9D while the field comes: the heading is absolute (ENU, magnetic north) -> close to the truth
    q_true = np.empty((n, 4))
    q_true[0] = quat.from_rotvec([0.2, -0.1, 0.4])
    steps = quat.from_rotvec(gyr[1:] / RATE)
    for i in range(1, n):
        q_true[i] = quat.multiply(q_true[i - 1], steps[i - 1])
    heading = np.degrees(quat.heading_error(q_true, quats(got)))
    assert heading[int(3 * RATE): n // 2].max() < 3.0, heading[int(3 * RATE): n // 2].max()
    assert heading[stale_from: 3 * n // 4].max() < 3.0  # held by the gyro while the field is gone
    # diagnostics named the fallback, and the return to 9D; the yaw covariance follows
    assert any(v == FIELD_STALE for v in states_gone), states_gone[-5:]
    final = [kv.value for s in diags.messages[-1].status for kv in s.values if kv.key == "magnetometer"]
    assert final == [FIELD_USED]
    # imu/data's covariance is the offline σ (orientation_covariance: model), SPD on every message; the yaw σ is the
    # field's while it corrects and grows while the field is gone
    cov = np.array([m.orientation_covariance for m in imu_out.messages])
    assert len(cov) == n
    want = np.zeros((n, 9))
    want[:, 0] = want[:, 4] = sigma[:, 0] ** 2
    want[:, 8] = sigma[:, 1] ** 2
    assert np.abs(cov - want).max() < 1e-6
    assert (np.linalg.eigvalsh(cov.reshape(n, 3, 3)) > 0.0).all()
    yaw_sd = np.degrees(np.sqrt(cov[:, 8]))
    corrected = yaw_sd[int(3 * RATE): n // 2]  # the field's 2.6° and the tilt's share (the bias still unknown here)
    held = yaw_sd[stale_from + int(RATE): 3 * n // 4]
    assert 2.6 <= corrected.min() and corrected.max() < 30.0 and 2.6 <= yaw_sd[-1] < 30.0
    assert held.max() < 180.0 and held.max() > yaw_sd[-1]  # the gyro's drift while the field is gone
    log = node.output()
    assert f"magnetometer: {FIELD_STALE}" in log and f"magnetometer: {FIELD_USED}" in log
    ros.destroy(pub_imu, pub_mag2, att, imu_out, diags)
