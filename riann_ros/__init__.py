"""riann_ros: plug-and-play IMU attitude estimation (RIANN and classical filters) for ROS 2.

The package is split in three rooms:

* the ROS-free core (this package's top-level modules, ``estimators``, ``datasets``) — estimation,
  quaternion math, metrics, dataset readers and bag I/O; importable without rclpy;
* the ROS layer (``riann_ros.nodes``) — one shared node base and thin per-estimator nodes;
* the command-line tools (``riann_ros.cli``) — thin verbs over the core, and the evaluator's DDS replay
  (``riann_ros.cli.live``, ``riann-bag-eval --live``): ROS glue that imports the evaluator.
"""

__version__ = "0.1.0"
