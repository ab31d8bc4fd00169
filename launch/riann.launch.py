"""riann_node on one IMU, with its parameter file and the usual overrides.

    ros2 launch riann_ros riann.launch.py
    ros2 launch riann_ros riann.launch.py input_topic:=/my_imu/data_raw nominal_rate:=200 world_frame:=ned
    ros2 launch riann_ros riann.launch.py params_file:=/path/to/my_riann.yaml attitude_topic:=/robot/imu/attitude
    ros2 launch riann_ros riann.launch.py namespace:=robot1 mag_topic:=/robot1/magnetometer

Parameters come from ``params_file`` (default: ``config/riann.yaml`` of the package share). The
arguments ``nominal_rate``, ``world_frame``, ``fixed_frame``, ``publish_tf`` and ``publish_rpy`` override
the file only when given: their default is empty, so a value set in your own ``params_file`` is not
silently replaced by a launch default. Topics: ``input_topic`` remaps ``imu/data_raw``, ``mag_topic``
``imu/mag``; ``attitude_topic``, ``imu_topic`` and ``rpy_topic`` remap the outputs. ``namespace`` puts the
node (and every relative topic name) under a namespace. See docs/node.md.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from launch import LaunchDescription
from riann_ros.params import launch_overrides

PACKAGE = "riann_ros"
NODE = "riann"  # executable riann_node, parameters config/riann.yaml
INPUT_TOPIC = "imu/data_raw"  # riann_ros.nodes.node_base.INPUT_TOPIC
MAG_TOPIC = "imu/mag"  # riann_ros.nodes.node_base.MAG_TOPIC
# launch argument -> the node's default output topic it remaps (RiannNode.ATTITUDE_TOPIC, IMU_TOPIC, rpy topic)
OUTPUT_TOPICS = {"attitude_topic": "imu/attitude", "imu_topic": "imu/data", "rpy_topic": "imu/rpy"}
# launch argument = node parameter -> (type, description); empty = the value of params_file
PARAMETER_ARGUMENTS = {
    "nominal_rate": ("float", "Hz; your IMU's rate: dt of the first sample after a (re)start (warned if wrong)"),
    "world_frame": ("str", "enu | ned | nwu: world frame of the published orientation"),
    "fixed_frame": ("str", "frame_id of imu/attitude and imu/rpy, parent frame of the TF"),
    "publish_tf": ("bool", "true: broadcast fixed_frame -> sensor frame on /tf (needs tf2_msgs)"),
    "publish_rpy": ("bool", "true: roll, pitch, yaw in degrees on imu/rpy"),
}



def _node(context):
    overrides = launch_overrides(PARAMETER_ARGUMENTS,
                                 {name: LaunchConfiguration(name).perform(context) for name in PARAMETER_ARGUMENTS})
    parameters = [LaunchConfiguration("params_file").perform(context)]
    if overrides:
        parameters.append(overrides)
    remappings = [(INPUT_TOPIC, LaunchConfiguration("input_topic").perform(context)),
                  (MAG_TOPIC, LaunchConfiguration("mag_topic").perform(context))]
    remappings += [(topic, LaunchConfiguration(arg).perform(context)) for arg, topic in OUTPUT_TOPICS.items()]
    return [Node(
        package=PACKAGE,
        executable=f"{NODE}_node",
        name=f"{NODE}_node",
        namespace=LaunchConfiguration("namespace").perform(context) or None,
        output="screen",
        parameters=parameters,
        remappings=remappings,
    )]


def generate_launch_description() -> LaunchDescription:
    share = get_package_share_directory(PACKAGE)
    actions = [
        DeclareLaunchArgument("params_file", default_value=os.path.join(share, "config", f"{NODE}.yaml"),
                              description="YAML parameter file of the node"),
        DeclareLaunchArgument("input_topic", default_value=INPUT_TOPIC,
                              description="IMU topic (sensor_msgs/Imu, REP-145) the node subscribes"),
        DeclareLaunchArgument("mag_topic", default_value=MAG_TOPIC,
                              description="magnetometer topic (sensor_msgs/MagneticField, tesla) the node subscribes"),
        DeclareLaunchArgument("namespace", default_value="",
                              description="namespace of the node and its relative topics (empty: none)"),
    ]
    for arg, topic in OUTPUT_TOPICS.items():
        actions.append(DeclareLaunchArgument(arg, default_value=topic, description=f"remap of {topic}"))
    for name, (kind, text) in PARAMETER_ARGUMENTS.items():
        actions.append(DeclareLaunchArgument(name, default_value="",
                                             description=f"{text} ({kind}; empty: the value in params_file)"))
    actions.append(OpaqueFunction(function=_node))
    return LaunchDescription(actions)
