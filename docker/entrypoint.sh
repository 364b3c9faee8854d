#!/usr/bin/env bash
# Sources ROS 2 and the lidar_har workspace, then runs the given command.
set -e
source /opt/ros/jazzy/setup.bash
source /ws/install/setup.bash
exec "$@"
