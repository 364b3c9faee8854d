"""rviz2 on a laptop with the saved lidar_har view: map, scan, person, activity text, alerts.

    ros2 launch lidar_har rviz.launch.py                    # live robot
    ros2 launch lidar_har rviz.launch.py use_sim_time:=true # while a bag is replayed
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue


def generate_launch_description():
    share = get_package_share_directory("lidar_har")
    return LaunchDescription([
        DeclareLaunchArgument("use_sim_time", default_value="false", description="follow /clock"),
        DeclareLaunchArgument("rviz_config", default_value=os.path.join(share, "config", "lidar_har.rviz"),
                              description="rviz2 configuration file"),
        Node(package="rviz2", executable="rviz2", name="rviz2", output="screen",
             arguments=["-d", LaunchConfiguration("rviz_config")],
             parameters=[{"use_sim_time": ParameterValue(LaunchConfiguration("use_sim_time"), value_type=bool)}]),
    ])
