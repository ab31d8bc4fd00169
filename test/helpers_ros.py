"""Helpers for node tests: IMU messages from arrays, flow-controlled publishing."""

from __future__ import annotations

import time

import numpy as np
from sensor_msgs.msg import Imu

from riann_ros import stamps


def imu_msg(stamp_ns: int, acc, gyr, frame_id: str = "imu_link") -> Imu:
    m = Imu()
    stamps.set_ns(m.header.stamp, stamp_ns)
    m.header.frame_id = frame_id
    m.orientation_covariance[0] = -1.0
    m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z = (float(v) for v in acc)
    m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z = (float(v) for v in gyr)
    return m


def stamp_ns(msg) -> int:
    return stamps.to_ns(msg.header.stamp)


def publish_paced(pub, msgs: list[Imu], received, expected_out, window: int = 100, stall: float = 60.0) -> None:
    """Publish ``msgs`` keeping at most ``window`` in flight: ``expected_out(i)`` = outputs due after i sent. Fails
    only when no output arrives for ``stall`` seconds (a stalled node), however long the whole takes (a loaded
    machine is slow, not wrong: speed is measured by the benchmarks)."""
    seen, last = len(received), time.monotonic()

    def progressing() -> bool:
        nonlocal seen, last
        if len(received) != seen:
            seen, last = len(received), time.monotonic()
        return time.monotonic() - last < stall

    for i, m in enumerate(msgs):
        while i - len(received) >= window:
            if not progressing():
                raise AssertionError(f"node stalled: {len(received)} outputs after {i} inputs")
            time.sleep(0.0002)
        pub.publish(m)
    while len(received) < expected_out and progressing():
        time.sleep(0.01)


def quats(msgs) -> np.ndarray:
    return np.array([[m.quaternion.w, m.quaternion.x, m.quaternion.y, m.quaternion.z] for m in msgs])
