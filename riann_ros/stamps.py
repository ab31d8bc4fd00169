"""Time stamps: ROS ``builtin_interfaces/Time`` (sec, nanosec) ↔ integer nanoseconds, and dt (ROS-free).

The project keeps every sample time as an ``int`` / ``int64`` count of nanoseconds; these helpers are the
one place that converts, duck-typed on any object with ``sec`` and ``nanosec`` (rclpy or rosbags messages).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from riann_ros.constants import NS_PER_S


def to_ns(stamp: Any) -> int:
    """Nanoseconds of a ``builtin_interfaces/Time``-like stamp."""
    return stamp.sec * NS_PER_S + stamp.nanosec


def split_ns(ns: Any) -> tuple[Any, Any]:
    """(sec, nanosec) of nanosecond stamps, an int or an int64 array (nanosec in [0, 1e9), also before 1970)."""
    sec = ns // NS_PER_S
    return sec, ns - sec * NS_PER_S


def join_ns(sec: ArrayLike, nanosec: ArrayLike) -> NDArray[np.int64]:
    """Nanoseconds (int64) from ``sec`` and ``nanosec`` (ints or integer arrays)."""
    return np.asarray(sec, dtype=np.int64) * NS_PER_S + np.asarray(nanosec, dtype=np.int64)


def set_ns(stamp: Any, ns: int) -> None:
    """Write a nanosecond count into a ``builtin_interfaces/Time``-like stamp."""
    stamp.sec, stamp.nanosec = split_ns(int(ns))


def dts(stamps_ns: ArrayLike, first_dt: float) -> NDArray[np.float64]:
    """Per-sample dt (s) of a stamp sequence as the input gate gives it: ``first_dt`` (the gate's
    ``1 / nominal_rate``) for the first sample, stamp differences after it."""
    st = np.asarray(stamps_ns, dtype=np.int64)
    out = np.empty(len(st), dtype=np.float64)
    if len(st):
        out[0] = first_dt
        out[1:] = np.diff(st) * 1e-9
    return out
