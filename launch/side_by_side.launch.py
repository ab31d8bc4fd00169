"""RIANN, Madgwick, Mahony and VQF side by side on one IMU input.

    ros2 launch riann_ros side_by_side.launch.py
    ros2 launch riann_ros side_by_side.launch.py input_topic:=/my_imu/data_raw nominal_rate:=200.0

Each node loads its parameter file from the package share (``config/<name>.yaml``) and publishes on
its own default topics (``imu/attitude`` + ``imu/data`` for RIANN, ``imu/<name>/attitude`` +
``imu/<name>/data`` for the others), so nothing collides; all four subscribe the same input.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

from launch import LaunchDescription

PACKAGE = "riann_ros"
NODES = ("riann", "madgwick", "mahony", "vqf")  # executable <name>_node, parameters config/<name>.yaml
INPUT_TOPIC = "imu/data_raw"  # the topic every node subscribes (riann_ros.nodes.node_base.INPUT_TOPIC)


def generate_launch_description() -> LaunchDescription:
    share = get_package_share_directory(PACKAGE)
    input_topic = LaunchConfiguration("input_topic")
    nominal_rate = LaunchConfiguration("nominal_rate")
    actions = [
        DeclareLaunchArgument("input_topic", default_value=INPUT_TOPIC,
                              description="IMU topic (sensor_msgs/Imu) all four nodes subscribe"),
        DeclareLaunchArgument("nominal_rate", default_value="100.0",
                              description="Hz; dt of the first sample after a (re)start, and VQF's sample time"),
    ]
    for name in NODES:
        actions.append(Node(
            package=PACKAGE,
            executable=f"{name}_node",
            name=f"{name}_node",
            output="screen",
            parameters=[os.path.join(share, "config", f"{name}.yaml"),
                        {"nominal_rate": ParameterValue(nominal_rate, value_type=float)}],
            remappings=[(INPUT_TOPIC, input_topic)],
        ))
    return LaunchDescription(actions)
