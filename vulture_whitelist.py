"""Names vulture (the dead-code check of ``make lint``) cannot see being used: read by a framework, a message, or by
name. Never executed; each entry says who uses it. Dead code is deleted, not listed here."""

# ROS message and service fields the nodes set; rclpy serialises them (riann_ros/nodes/node_base.py)
_.integer_range  # rcl_interfaces/ParameterDescriptor
_.floating_point_range  # rcl_interfaces/ParameterDescriptor
_.hardware_id  # diagnostic_msgs/DiagnosticStatus

# ONNX Runtime session options, read by onnxruntime (riann_ros/estimators/riann/s4b_model.py, bench/output_guard.py)
_.intra_op_num_threads
_.inter_op_num_threads
_.log_severity_level
_.enable_cpu_mem_arena

# dataclass fields written out by name (asdict / getattr in to_dict) into results.csv and results.json
estimator_name  # riann_ros/evaluation/results.py ResultRow
max_err_deg  # riann_ros/evaluation/scoring.py Score
# evo ape's statistics of Score, read by name (Score.stat: getattr of stat_field(error, stat)) and written out
mean_err_deg
median_err_deg
std_err_deg
min_err_deg
heading_mean_deg
heading_median_deg
heading_std_deg
heading_min_deg
heading_max_deg
total_mean_deg
total_median_deg
total_std_deg
total_min_deg
total_max_deg
heading_drift_mean_deg
heading_drift_median_deg
heading_drift_std_deg

# pytest and launch, in the tests: the module's test marks; a launch substitution's hook; ROS request fields
pytestmark
running  # test/test_cli_topic.py: a fixture the tests take by name
_.perform  # test/helpers_launch.py LaunchConfiguration stand-in, called by the launch description walk
_.parameters  # rcl_interfaces/SetParameters.Request, GetParameters.Request
_.string_value  # rcl_interfaces/ParameterValue
