"""RIANN, Madgwick, Mahony, VQF and the RIANN–VQF consensus side by side on one IMU input.

    ros2 launch riann_ros side_by_side.launch.py
    ros2 launch riann_ros side_by_side.launch.py input_topic:=/my_imu/data_raw nominal_rate:=200.0
    ros2 launch riann_ros side_by_side.launch.py namespace:=robot1 mag_topic:=/robot1/magnetometer
    ros2 launch riann_ros side_by_side.launch.py publish_rpy:=true   # then config/foxglove_side_by_side.json

Each node loads its parameter file from the package share (``config/<name>.yaml``) and publishes on
its own default topics (``imu/attitude`` + ``imu/data`` (+ ``imu/rpy``) for RIANN, ``imu/<name>/attitude`` +
``imu/<name>/data`` (+ ``imu/<name>/rpy``) for the others), so nothing collides; all five subscribe the
same input (``input_topic``) and magnetometer (``mag_topic``), under ``namespace``. ``nominal_rate``,
``world_frame``, ``fixed_frame`` and ``publish_rpy`` go to all five, ``publish_tf`` to riann_node only (five
nodes broadcasting the same fixed_frame -> sensor frame transform would fight over it). These five default
to empty, which means "the value in the parameter files": a launch default never replaces a value you set
there. See docs/node.md.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from launch import LaunchDescription
from riann_ros.params import launch_overrides

PACKAGE = "riann_ros"
NODES = ("riann", "madgwick", "mahony", "vqf", "consensus")  # executable <name>_node, parameters config/<name>.yaml
INPUT_TOPIC = "imu/data_raw"  # the topic every node subscribes (riann_ros.nodes.node_base.INPUT_TOPIC)
MAG_TOPIC = "imu/mag"  # riann_ros.nodes.node_base.MAG_TOPIC
TF_NODE = "riann"  # the one node that broadcasts TF when publish_tf:=true
# launch argument = node parameter -> (type, description); empty = the value of the parameter files
PARAMETER_ARGUMENTS = {
    "nominal_rate": ("float", "Hz; dt of the first sample after a (re)start, and VQF's sample time"),
    "world_frame": ("str", "enu | ned | nwu: world frame of the published orientations"),
    "fixed_frame": ("str", "frame_id of the attitude and rpy topics, parent frame of the TF"),
    "publish_tf": ("bool", f"true: {TF_NODE}_node broadcasts fixed_frame -> sensor frame on /tf"),
    "publish_rpy": ("bool", "true: roll, pitch, yaw in degrees on imu/rpy, imu/<name>/rpy"),
}



def _nodes(context):
    share = get_package_share_directory(PACKAGE)
    given = launch_overrides(PARAMETER_ARGUMENTS,
                             {name: LaunchConfiguration(name).perform(context) for name in PARAMETER_ARGUMENTS})
    remappings = [(INPUT_TOPIC, LaunchConfiguration("input_topic").perform(context)),
                  (MAG_TOPIC, LaunchConfiguration("mag_topic").perform(context))]
    nodes = []
    for name in NODES:
        overrides = {k: v for k, v in given.items() if k != "publish_tf" or name == TF_NODE}
        nodes.append(Node(
            package=PACKAGE,
            executable=f"{name}_node",
            name=f"{name}_node",
            namespace=LaunchConfiguration("namespace").perform(context) or None,
            output="screen",
            parameters=[os.path.join(share, "config", f"{name}.yaml"), *([overrides] if overrides else [])],
            remappings=remappings,
        ))
    return nodes


def generate_launch_description() -> LaunchDescription:
    actions = [
        DeclareLaunchArgument("input_topic", default_value=INPUT_TOPIC,
                              description="IMU topic (sensor_msgs/Imu) all five nodes subscribe"),
        DeclareLaunchArgument("mag_topic", default_value=MAG_TOPIC,
                              description="magnetometer topic (sensor_msgs/MagneticField) all five nodes subscribe"),
        DeclareLaunchArgument("namespace", default_value="",
                              description="namespace of the five nodes and their relative topics (empty: none)"),
    ]
    for name, (kind, text) in PARAMETER_ARGUMENTS.items():
        actions.append(DeclareLaunchArgument(name, default_value="",
                                             description=f"{text} ({kind}; empty: the value in the parameter files)"))
    actions.append(OpaqueFunction(function=_nodes))
    return LaunchDescription(actions)
