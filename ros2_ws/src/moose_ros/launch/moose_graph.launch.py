"""ROS 2 launch of the moose graph:
`ros2 launch moose_ros moose_graph.launch.py [group:=all|perception|planning|control|vehicle|bridge]
[lockstep:=true]`.

Groups mirror the vehicle's ECUs (moose_ros.graph.GROUPS): perception (observer, obstacle
detector), planning (MPC, MSF, weight function + FBL; the MicroLabBox), control (motion
controller; the AutoBox), vehicle (the plant simulator) and bridge (the CAN bridge, which replaces
the simulator on the car: ``with_simulator:=false``).  Which nodes start and the parameters each
gets are ``moose launch``'s (:func:`moose_ros.launch.node_overrides` of the graph ``full``, or
``car`` without the simulator; :func:`node_parameters` here, checked by tests/test_graph_contract.py):
only the parameters a node takes, simulated time where the simulator publishes /clock, the
scenario's road friction for every node, and the simulator waits for every other node of the
graph (whichever group launches them) before it starts the clock.  ``lockstep:=true`` runs the graph in lockstep
(``moose launch --lockstep``, :mod:`moose_ros.lockstep`; with the simulator only).
"""
import typing

from moose.scenario import DEFAULT_SCENARIO
from moose.schema import PlannerMode
from moose_ros.graph import GROUPS


def node_parameters(group: str, with_simulator: bool, scenario: str, planner: str,
                    params_file: str = "", lockstep: bool = False) -> dict[str, list]:
    """``{node: parameters}`` of the nodes this launch starts: the parameter file (if any), then the
    overrides ``moose launch`` gives the node (which win)."""
    from moose.scenario import load_scenario
    from moose_ros.launch import node_overrides

    mu = load_scenario(scenario).mu
    given = {"scenario": scenario, **({"vehicle.mu": mu} if mu is not None else {})}  # as moose launch
    overrides = node_overrides("full" if with_simulator else "car", planner, given, params_file or None,
                               lockstep=lockstep)
    return {name: ([params_file] if params_file else []) + [values] for name, values in overrides.items()
            if group == "all" or name in GROUPS[group]}


def nodes(context, *args, **kwargs):
    from launch.substitutions import LaunchConfiguration
    from launch_ros.actions import Node

    value = {key: LaunchConfiguration(key).perform(context)
             for key in ("group", "with_simulator", "scenario", "planner", "params_file", "lockstep")}
    chosen = node_parameters(value["group"], value["with_simulator"] == "true", value["scenario"], value["planner"],
                             value["params_file"], value["lockstep"] == "true")
    return [Node(package="moose_ros", executable=name, name=name, output="screen", parameters=parameters)
            for name, parameters in chosen.items()]


def generate_launch_description():
    from launch import LaunchDescription
    from launch.actions import DeclareLaunchArgument, OpaqueFunction

    return LaunchDescription([
        DeclareLaunchArgument("group", default_value="all", choices=["all", *GROUPS]),
        DeclareLaunchArgument("with_simulator", default_value="true", choices=["true", "false"]),
        DeclareLaunchArgument("scenario", default_value=DEFAULT_SCENARIO),
        DeclareLaunchArgument("planner", default_value="combined", choices=list(typing.get_args(PlannerMode))),
        DeclareLaunchArgument("params_file", default_value=""),
        DeclareLaunchArgument("lockstep", default_value="false", choices=["true", "false"]),
        OpaqueFunction(function=nodes),
    ])
