"""Robot bring-up: RPLIDAR driver, localiser and classifier (and optionally rviz2).

    ros2 launch lidar_har robot.launch.py serial_port:=/dev/ttyUSB0
    ros2 launch lidar_har robot.launch.py serial_port:=/dev/rplidar baud:=1000000   # S2/S3
    ros2 launch lidar_har robot.launch.py scan_mode:=Sensitivity frame_id:=base_laser
    ros2 launch lidar_har robot.launch.py use_classifier:=false   # tracking only

baud by model: 115200 for A1 and A2M8, 256000 for A2M12, A3 and S1, 460800 for C1, 1000000 for S2 and S3.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue


def generate_launch_description():
    share = get_package_share_directory("lidar_har")
    config = os.path.join(share, "config")
    arg = LaunchConfiguration
    return LaunchDescription([
        DeclareLaunchArgument("use_driver", default_value="true", description="start rplidar_driver"),
        DeclareLaunchArgument("use_localiser", default_value="true", description="start the localiser"),
        DeclareLaunchArgument("use_classifier", default_value="true", description="start the classifier"),
        DeclareLaunchArgument("use_rviz", default_value="false", description="start rviz2 with config/lidar_har.rviz"),
        DeclareLaunchArgument("log_level", default_value="info",
                              description="severity of the lidar_har nodes' logs (stderr and /rosout): "
                                          "debug, info, warn, error or fatal"),
        DeclareLaunchArgument("serial_port", default_value="/dev/ttyUSB0",
                              description="RPLIDAR serial device (driver parameter port)"),
        DeclareLaunchArgument("baud", default_value="115200",
                              description="RPLIDAR baud rate: 115200 A1, A2M8; 256000 A2M12, A3, S1; "
                                          "460800 C1; 1000000 S2, S3"),
        DeclareLaunchArgument("scan_mode", default_value="auto",
                              description="auto (the device's typical mode), standard, express or a mode "
                                          "name the device lists (Sensitivity, Boost, DenseBoost, ...)"),
        DeclareLaunchArgument("frame_id", default_value="laser", description="frame of the published scans"),
        DeclareLaunchArgument("params_file", default_value=os.path.join(config, "robot.yaml"),
                              description="parameters of all nodes (ROS 2 params-file layout)"),
        # With a namespace (`namespace=""`: the root one) launch_ros files the dict below under
        # the node's full name, /rplidar_driver, instead of `/**`: rcl merges the sections of all
        # parameter files in the order each name first appears, and rclcpp applies them in that
        # order, so a `/**` dict lost to a params_file with `/**:` before `rplidar_driver:`.
        # Under its own name the dict comes last and wins, unless params_file names the node
        # `/rplidar_driver` itself and has another section for it after that one.
        Node(package="lidar_har", executable="rplidar_driver", name="rplidar_driver", namespace="",
             output="screen",
             ros_arguments=["--log-level", arg("log_level")],
             parameters=[arg("params_file"), {
                 # Strings as given: a port, mode or frame name must not be read as YAML
                 # (on, 1, 2024_01_01, ...).
                 "port": ParameterValue(arg("serial_port"), value_type=str),
                 "baud": ParameterValue(arg("baud"), value_type=int),
                 "scan_mode": ParameterValue(arg("scan_mode"), value_type=str),
                 "frame_id": ParameterValue(arg("frame_id"), value_type=str),
             }],
             condition=IfCondition(arg("use_driver"))),
        Node(package="lidar_har", executable="localiser", name="localiser", output="screen",
             ros_arguments=["--log-level", arg("log_level")],
             parameters=[{"config": os.path.join(config, "localiser.yaml")}, arg("params_file")],
             condition=IfCondition(arg("use_localiser"))),
        Node(package="lidar_har", executable="classifier", name="classifier", output="screen",
             ros_arguments=["--log-level", arg("log_level")],
             # The installed files first: the params file's keys win over them.
             parameters=[{"config": os.path.join(config, "classifier.yaml"),
                          "model": os.path.join(share, "models", "activity.onnx"),
                          "pose_head": os.path.join(share, "models", "pose_head.onnx")}, arg("params_file")],
             condition=IfCondition(arg("use_classifier"))),
        Node(package="rviz2", executable="rviz2", name="rviz2", output="screen",
             arguments=["-d", os.path.join(config, "lidar_har.rviz")],
             condition=IfCondition(arg("use_rviz"))),
    ])
