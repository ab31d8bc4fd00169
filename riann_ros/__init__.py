"""riann_ros: plug-and-play IMU attitude estimation (RIANN and classical filters) for ROS 2.

The package is split in three rooms:

* the ROS-free core (this package's top-level modules, ``estimators``, ``magcal``, ``datasets``, ``bagio``,
  ``evaluation``) — estimation, quaternion math, metrics, dataset readers, bag I/O and the evaluator; importable
  without rclpy;
* the ROS layer — the nodes (``riann_ros.nodes``: one shared node base and thin per-estimator nodes) and the tools
  that talk to them over DDS (``riann_ros.ros``: the evaluator's DDS replay, ``riann-topic``'s graph reader); it
  imports the core, never the evaluator or the command-line tools;
* the command-line tools (``riann_ros.cli``) — thin verbs over the core, wiring in the ROS layer where a verb needs
  it (``riann-bag-eval --live``, ``riann-topic``), importing no ROS package themselves.
"""

__version__ = "0.1.0"
