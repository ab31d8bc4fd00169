"""RIANN, Madgwick, Mahony and VQF side by side on one IMU input.

    ros2 launch riann_ros side_by_side.launch.py
    ros2 launch riann_ros side_by_side.launch.py input_topic:=/my_imu/data_raw nominal_rate:=200.0
    ros2 launch riann_ros side_by_side.launch.py publish_rpy:=true   # then config/foxglove_side_by_side.json

Each node loads its parameter file from the package share (``config/<name>.yaml``) and publishes on
its own default topics (``imu/attitude`` + ``imu/data`` (+ ``imu/rpy``) for RIANN, ``imu/<name>/attitude`` +
``imu/<name>/data`` (+ ``imu/<name>/rpy``) for the others), so nothing collides; all four subscribe the
same input. ``nominal_rate``, ``world_frame``, ``fixed_frame`` and ``publish_rpy`` go to all four;
``publish_tf`` to riann_node only (four nodes broadcasting the same fixed_frame -> sensor frame transform
would fight over it).
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
TF_NODE = "riann"  # the one node that broadcasts TF when publish_tf:=true


def generate_launch_description() -> LaunchDescription:
    share = get_package_share_directory(PACKAGE)
    input_topic = LaunchConfiguration("input_topic")
    shared = {
        "nominal_rate": ParameterValue(LaunchConfiguration("nominal_rate"), value_type=float),
        "world_frame": ParameterValue(LaunchConfiguration("world_frame"), value_type=str),
        "fixed_frame": ParameterValue(LaunchConfiguration("fixed_frame"), value_type=str),
        "publish_rpy": ParameterValue(LaunchConfiguration("publish_rpy"), value_type=bool),
    }
    publish_tf = ParameterValue(LaunchConfiguration("publish_tf"), value_type=bool)
    actions = [
        DeclareLaunchArgument("input_topic", default_value=INPUT_TOPIC,
                              description="IMU topic (sensor_msgs/Imu) all four nodes subscribe"),
        DeclareLaunchArgument("nominal_rate", default_value="100.0",
                              description="Hz; dt of the first sample after a (re)start, and VQF's sample time"),
        DeclareLaunchArgument("world_frame", default_value="enu",
                              description="enu | ned | nwu: world frame of the published orientations"),
        DeclareLaunchArgument("fixed_frame", default_value="odom",
                              description="frame_id of the attitude and rpy topics, parent frame of the TF"),
        DeclareLaunchArgument("publish_tf", default_value="false",
                              description=f"true: {TF_NODE}_node broadcasts fixed_frame -> sensor frame on /tf"),
        DeclareLaunchArgument("publish_rpy", default_value="false",
                              description="true: roll, pitch, yaw in degrees on imu/rpy, imu/<name>/rpy"),
    ]
    for name in NODES:
        params = {**shared, **({"publish_tf": publish_tf} if name == TF_NODE else {})}
        actions.append(Node(
            package=PACKAGE,
            executable=f"{name}_node",
            name=f"{name}_node",
            output="screen",
            parameters=[os.path.join(share, "config", f"{name}.yaml"), params],
            remappings=[(INPUT_TOPIC, input_topic)],
        ))
    return LaunchDescription(actions)
