"""Time stamps: ROS ``builtin_interfaces/Time`` (sec, nanosec) ↔ integer nanoseconds, and dt (ROS-free).

The project keeps every sample time as an ``int`` / ``int64`` count of nanoseconds; these helpers are the
one place that converts, duck-typed on any object with ``sec`` and ``nanosec`` (rclpy or rosbags messages).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

NS_PER_S = 1_000_000_000


def to_ns(stamp: Any) -> int:
    """Nanoseconds of a ``builtin_interfaces/Time``-like stamp."""
    return stamp.sec * NS_PER_S + stamp.nanosec


def split_ns(ns: int) -> tuple[int, int]:
    """(sec, nanosec) of a nanosecond count (nanosec in [0, 1e9), also for negative times)."""
    sec, nsec = divmod(int(ns), NS_PER_S)
    return sec, nsec


def set_ns(stamp: Any, ns: int) -> None:
    """Write a nanosecond count into a ``builtin_interfaces/Time``-like stamp."""
    stamp.sec, stamp.nanosec = split_ns(ns)


def seconds(ns: ArrayLike) -> NDArray[np.float64]:
    """Nanoseconds (scalar or array) as seconds (float64)."""
    return np.asarray(ns, dtype=np.int64) * 1e-9


def dts(stamps_ns: ArrayLike, first_dt: float) -> NDArray[np.float64]:
    """Per-sample dt (s) of a stamp sequence as the input gate gives it: ``first_dt`` (the gate's
    ``1 / nominal_rate``) for the first sample, stamp differences after it."""
    st = np.asarray(stamps_ns, dtype=np.int64)
    return np.concatenate([[first_dt], np.diff(st) * 1e-9]) if len(st) else np.zeros(0)
