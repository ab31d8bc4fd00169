"""Names vulture (the dead-code check of ``make lint``) cannot see being used: read by a framework, a message, or by
name. Never executed; each entry says who uses it. Dead code is deleted, not listed here."""

# ROS message and service fields the nodes set; rclpy serialises them (riann_ros/nodes/node_base.py)
_.integer_range  # rcl_interfaces/ParameterDescriptor
_.floating_point_range  # rcl_interfaces/ParameterDescriptor
_.hardware_id  # diagnostic_msgs/DiagnosticStatus

# ONNX Runtime session options, read by onnxruntime (riann_ros/estimators/riann.py make_session)
_.intra_op_num_threads
_.inter_op_num_threads
_.log_severity_level

# dataclass fields written out by name (asdict / getattr in to_dict) into results.csv and results.json
estimator_name  # riann_ros/evaluation/results.py ResultRow
max_err_deg  # riann_ros/evaluation/scoring.py Score

# pytest and launch, in the tests: the module's test marks; a launch substitution's hook; ROS request fields
pytestmark
_.perform  # test/test_node_files.py LaunchConfiguration stand-in, called by the launch description walk
_.parameters  # rcl_interfaces/SetParameters.Request, GetParameters.Request
_.string_value  # rcl_interfaces/ParameterValue

# The lead's, to remove with the estimator redesign (issue 24): the six core files are not edited on this branch.
DT_MAX  # riann_ros/estimators/grid.py: the slowest trained step, stated but never read
# A shared default waiting for its users: riann_ros/estimators/heading.py (MAG_HEADING_SD) and the node parameter
# mag_yaw_stddev_deg (riann_ros/nodes/node_base.py) still hold their own 5.0; when they point here, drop this line.
MAG_HEADING_SD_DEG  # riann_ros/defaults.py
