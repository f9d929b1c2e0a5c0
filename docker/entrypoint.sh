#!/usr/bin/env bash
# Source ROS 2 and the workspace overlay, then run the command.
set -e
source /opt/ros/jazzy/setup.bash
source /opt/moose/ros2_ws/install/setup.bash
exec "$@"
