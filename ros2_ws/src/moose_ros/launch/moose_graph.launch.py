"""ROS 2 launch of the moose graph: `ros2 launch moose_ros moose_graph.launch.py [group:=all|perception|planning|control|vehicle|bridge]`.

Groups mirror the vehicle's ECUs (moose_ros.graph.GROUPS): perception (observer, obstacle
detector), planning (MPC, MSF, weight function + FBL; the MicroLabBox), control (motion
controller; the AutoBox), vehicle (the plant simulator) and bridge (the CAN bridge, which replaces
the simulator on the car: ``with_simulator:=false``).  Each node gets only the parameters it takes
(moose_ros.parameters), as with ``moose launch``.
"""
import typing

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from moose.cli.common import DEFAULT_SCENARIO
from moose.schema import PlannerMode
from moose_ros.graph import GROUPS, NODES
from moose_ros.parameters import parameter_names


def nodes(context, *args, **kwargs):
    group = LaunchConfiguration("group").perform(context)
    names = list(NODES) if group == "all" else list(GROUPS[group])
    # with the simulator its topics stand in for the vehicle bus; on the car the CAN bridge does
    simulated = LaunchConfiguration("with_simulator").perform(context) == "true"
    excluded = "can_bridge" if simulated else "vehicle_simulator"
    names = [n for n in names if n != excluded]
    params_file = LaunchConfiguration("params_file").perform(context)
    given = {
        "scenario": LaunchConfiguration("scenario").perform(context),
        "simulation.planner": LaunchConfiguration("planner").perform(context),
    }

    def parameters(name):
        own = {k: v for k, v in given.items() if "." in k or k in parameter_names(name)}
        # simulated time only where the simulator publishes /clock; the car runs on wall-clock time
        own["use_sim_time"] = simulated and name != "vehicle_simulator"
        return [params_file, own] if params_file else [own]

    return [Node(package="moose_ros", executable=name, name=name, output="screen", parameters=parameters(name))
            for name in names]


def generate_launch_description():
    return LaunchDescription([
        DeclareLaunchArgument("group", default_value="all", choices=["all", *GROUPS]),
        DeclareLaunchArgument("with_simulator", default_value="true", choices=["true", "false"]),
        DeclareLaunchArgument("scenario", default_value=DEFAULT_SCENARIO),
        DeclareLaunchArgument("planner", default_value="combined", choices=list(typing.get_args(PlannerMode))),
        DeclareLaunchArgument("params_file", default_value=""),
        OpaqueFunction(function=nodes),
    ])
