"""The monitors of the input path: physics tests of what the stream is fed, run alike by the node and the evaluator
(ROS-free). :mod:`.base` (levels, verdicts, the σ they widen), :mod:`.gyro_units`, :mod:`.input_loss`,
:mod:`.field` (the magnetometer's readings and calibration); docs/node.md, "Monitors", lists each with its test and
what the node then does.
"""

from riann_ros.monitors.base import UNTRUSTED_SD_RAD, Level, Monitor, Monitors, Verdict

__all__ = ["UNTRUSTED_SD_RAD", "Level", "Monitor", "Monitors", "Verdict"]
