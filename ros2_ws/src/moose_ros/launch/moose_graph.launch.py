"""ROS 2 launch of the moose graph: `ros2 launch moose_ros moose_graph.launch.py [group:=all|perception|planning|control|vehicle]`.

Groups mirror the vehicle's ECUs: perception (observer, obstacle detector), planning
(MPC, MSF, weight function + FBL; the MicroLabBox), control (motion controller; the
AutoBox), vehicle (the plant simulator) and bridge (the CAN bridge, which replaces the
simulator on the car: ``with_simulator:=false``).
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

GROUPS = {
    "perception": ["observer", "obstacle_detector"],
    "planning": ["mpc_planner", "msf_planner", "weight_fbl"],
    "control": ["motion_controller"],
    "vehicle": ["vehicle_simulator"],
    "bridge": ["can_bridge"],
}


def nodes(context, *args, **kwargs):
    group = LaunchConfiguration("group").perform(context)
    names = [n for g in GROUPS.values() for n in g] if group == "all" else GROUPS[group]
    # with the simulator its topics stand in for the vehicle bus; on the car the CAN bridge does
    simulated = LaunchConfiguration("with_simulator").perform(context) == "true"
    excluded = "can_bridge" if simulated else "vehicle_simulator"
    names = [n for n in names if n != excluded]
    params_file = LaunchConfiguration("params_file").perform(context)
    common = {
        "scenario": LaunchConfiguration("scenario").perform(context),
        "planner": LaunchConfiguration("planner").perform(context),
    }
    def parameters(name):
        # simulated time only where the simulator publishes /clock; the car runs on wall-clock time
        own = dict(common, use_sim_time=simulated and name != "vehicle_simulator")
        return [params_file, own] if params_file else [own]

    return [Node(package="moose_ros", executable=name, name=name, output="screen", parameters=parameters(name))
            for name in names]


def generate_launch_description():
    return LaunchDescription([
        DeclareLaunchArgument("group", default_value="all", choices=["all", *GROUPS]),
        DeclareLaunchArgument("with_simulator", default_value="true", choices=["true", "false"]),
        DeclareLaunchArgument("scenario", default_value="paper_v7_tau1.4"),
        DeclareLaunchArgument("planner", default_value="combined", choices=["combined", "mpc", "msf"]),
        DeclareLaunchArgument("params_file", default_value=""),
        OpaqueFunction(function=nodes),
    ])
