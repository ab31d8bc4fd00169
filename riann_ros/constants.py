"""Physical constants and unit factors: one home for the whole package (ROS-free, no imports but ``math``).

Names carry their unit where a value crosses a module (``_deg``, ``_rad``, ``_ns``, ``_s``); multiply degrees by
:data:`DEG` to get radians, radians by :data:`RAD` to get degrees.
"""

from __future__ import annotations

import math

#: m/s²; standard gravity (ISO 80000-3, CGPM 1901): the ``g`` of accelerometer datasheets, of "1 g = 9.80665 m/s²"
#: unit conversions and of imu_tools' ``remove_gravity_vector``.
GRAVITY = 9.80665

#: rad in one degree.
DEG = math.pi / 180.0

#: degrees in one radian.
RAD = 180.0 / math.pi

#: ns in one second.
NS_PER_S = 1_000_000_000
