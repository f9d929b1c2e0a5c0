"""The graph that runs on the car: everything but the vehicle simulator (sensors come from the vehicle bus)."""
from launch import LaunchDescription
from launch.actions import IncludeLaunchDescription
from launch.launch_description_sources import PythonLaunchDescriptionSource
from launch.substitutions import PathJoinSubstitution
from launch_ros.substitutions import FindPackageShare


def generate_launch_description():
    return LaunchDescription([
        IncludeLaunchDescription(
            PythonLaunchDescriptionSource(
                PathJoinSubstitution([FindPackageShare("moose_ros"), "launch", "moose_graph.launch.py"])),
            launch_arguments={"with_simulator": "false"}.items(),
        )
    ])
