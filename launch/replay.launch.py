"""Bag replay: replay + localiser + classifier on the bag's clock (use_sim_time), no driver.

    ros2 launch lidar_har replay.launch.py bag:=/path/to/bag
    ros2 launch lidar_har replay.launch.py bag:=/path/to/bag rate:=4.0 use_rviz:=true
"""

import os
import tempfile

import yaml
from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue


def own_values_file(params):
    """A params file of the launch file's own values for one node, in the section `/**`.

    rcl merges all of a node's parameter files into one table of sections, in the order each
    section name first appears, and rclcpp applies them in that order, the last one winning.
    The launch file's own values are `/**`, first, so that params_file's sections come after
    them and win; the launch arguments are a dict after params_file, which launch_ros files
    under the node's full name (`/replay`) because the node has a namespace (`namespace=""`:
    the root one), so that they come last and win over every section of params_file unless
    it names the node `/replay` itself and has another section for it after that one. As a
    dict, these values would be under `/replay` too, first, and lose to the file again.
    """
    with tempfile.NamedTemporaryFile("w", prefix="lidar_har_params_", suffix=".yaml", delete=False) as file:
        yaml.safe_dump({"/**": {"ros__parameters": params}}, file)
        return file.name


def generate_launch_description():
    share = get_package_share_directory("lidar_har")
    config = os.path.join(share, "config")
    arg = LaunchConfiguration
    return LaunchDescription([
        DeclareLaunchArgument("bag", description="rosbag2 directory to play"),
        DeclareLaunchArgument("rate", default_value="1.0", description="playback speed; 0 = as fast as possible"),
        DeclareLaunchArgument("loop", default_value="false", description="play the bag in a loop"),
        DeclareLaunchArgument("use_localiser", default_value="true", description="start the localiser"),
        DeclareLaunchArgument("use_classifier", default_value="true", description="start the classifier"),
        DeclareLaunchArgument("use_rviz", default_value="false", description="start rviz2 with config/lidar_har.rviz"),
        DeclareLaunchArgument("log_level", default_value="info",
                              description="severity of the lidar_har nodes' logs (stderr and /rosout): "
                                          "debug, info, warn, error or fatal"),
        DeclareLaunchArgument("params_file", default_value=os.path.join(config, "replay.yaml"),
                              description="parameters of all nodes (ROS 2 params-file layout)"),
        Node(package="lidar_har", executable="replay", name="replay", namespace="", output="screen",
             ros_arguments=["--log-level", arg("log_level")],
             # Order and sections: see own_values_file.
             parameters=[own_values_file({
                 # Topics the nodes below publish themselves are not replayed from the bag.
                 # Those the bag lacks (a fixed Lidar has no /odom or /map) are skipped with a
                 # warning; replay fails only when the bag has none of them.
                 "topics": ["/scan", "/odom", "/map", "/tf", "/tf_static"],
             }), arg("params_file"), {
                 # A string as given: launch_ros reads an untyped value as YAML, and a bag
                 # named 2024_01_01 became the integer 20240101 (the replay then refused it).
                 "bag": ParameterValue(arg("bag"), value_type=str),
                 "rate": ParameterValue(arg("rate"), value_type=float),
                 "loop": ParameterValue(arg("loop"), value_type=bool),
             }]),
        Node(package="lidar_har", executable="localiser", name="localiser", namespace="", output="screen",
             ros_arguments=["--log-level", arg("log_level")],
             # On the bag's clock whatever params_file says: a `localiser: use_sim_time: false`
             # there used to win.
             parameters=[own_values_file({"config": os.path.join(config, "localiser.yaml")}), arg("params_file"),
                         {"use_sim_time": True}],
             condition=IfCondition(arg("use_localiser"))),
        Node(package="lidar_har", executable="classifier", name="classifier", namespace="", output="screen",
             ros_arguments=["--log-level", arg("log_level")],
             parameters=[own_values_file({"config": os.path.join(config, "classifier.yaml"),
                                          "model": os.path.join(share, "models", "activity.onnx"),
                                          "pose_head": os.path.join(share, "models", "pose_head.onnx")}),
                         arg("params_file"), {"use_sim_time": True}],
             condition=IfCondition(arg("use_classifier"))),
        Node(package="rviz2", executable="rviz2", name="rviz2", output="screen",
             arguments=["-d", os.path.join(config, "lidar_har.rviz")], parameters=[{"use_sim_time": True}],
             condition=IfCondition(arg("use_rviz"))),
    ])
