"""``moose launch [GRAPH]``: run the whole node graph as separate processes, summarised like ``moose simulate``.

Exit status: 0 ``clear``; 1 a failure outcome (``collision``, ``left_field``, ``lost_control``,
``stopped_short``); 2 bad input (nothing started); 3 ``incomplete`` (too little odometry, or the run was cut
short: SIGTERM, a node that failed to start, the simulator gone); 4 ``clear`` but degraded (a node failed,
stalled or was faulted, a fallback or a minimum-risk maneuver ran); 5 the bag or ``--json`` could not be written
(a full disk: the summary is printed above the error, the bag ends at its last checkpoint); 130 Ctrl-C.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
from typing import Any

from moose.cli.common import (
    add_scenario_arguments,
    add_timing_argument,
    check_output_dir,
    check_output_file,
    parse_settings,
    positive_float,
    run_folder,
    write_output,
)
from moose.cli.simulate import format_summary
from moose.files import OutputError
from moose.params import ParamError
from moose.scenario.args import scenario_from_args

from ..graph import GRAPHS
from ..live import DEFAULT_HOST, DEFAULT_PORT
from ..runtime import RUNTIMES


def add_subparser(subparsers: Any) -> None:
    launch = subparsers.add_parser("launch", help="run the whole node graph as separate processes")
    launch.add_argument("graph", nargs="?", default="full", choices=list(GRAPHS),
                        help="full (simulator on topics), car (CAN bridge, no simulator) or can (both over the DBC)")
    launch.add_argument("--can-interface", help="udp_multicast (default), socketcan or virtual")
    launch.add_argument("--can-channel",
                        help="multicast group (default: moose.canbus.bus.DEFAULT_GROUP) / socketcan device")
    launch.add_argument("--can-port", type=int,
                        help="UDP port of udp_multicast (default: moose.canbus.bus.DEFAULT_PORT)")
    add_scenario_arguments(launch)
    launch.add_argument("--runtime", choices=RUNTIMES,
                        help="what the nodes run on: rclpy (ROS 2; the interpreter of .venv-ros when this one has no "
                             "rclpy) or dds (Cyclone DDS); default: MOOSE_RUNTIME, else rclpy when importable here")
    add_timing_argument(launch)
    launch.add_argument("--set", action="append", default=[], metavar="GROUP.KEY=VALUE",
                        help="change one value of the configuration for every node (e.g. timing.compensate=true)")
    launch.add_argument("--rate", type=positive_float, default=1.0, help="simulated seconds per wall-clock second")
    launch.add_argument("--lockstep", action="store_true",
                        help="step simulated time only when every node has handled the tick: the graph computes what "
                             "moose simulate computes, at whatever speed the machine allows (--rate is not used)")
    launch.add_argument("--fault", action="append", default=[], metavar="NODE:kill@T|NODE:stall@T:D",
                        help="inject a fault: SIGKILL NODE at simulated time T, or SIGSTOP it at T for D simulated "
                             "seconds (repeatable)")
    launch.add_argument("--json", help="write the summary as JSON to this path")
    launch.add_argument("--bag", help="record every topic into this bag directory (default: a new folder under runs/)")
    launch.add_argument("--no-bag", action="store_true", help="do not record a bag")
    launch.add_argument("--foxglove", nargs="?", type=int, const=DEFAULT_PORT, metavar="PORT",
                        help="serve the live graph to Foxglove over its WebSocket protocol "
                             f"(default port {DEFAULT_PORT})")
    launch.add_argument("--foxglove-host", default=DEFAULT_HOST,
                        help=f"address the live view binds to (default {DEFAULT_HOST}: this machine only)")
    launch.set_defaults(func=cmd_launch)


def cmd_launch(args: argparse.Namespace) -> int:
    from ..bag import BagError
    from ..faults import Fault
    from ..launch import launch, planner_mode
    from ..parameters import NodeParams, ScenarioParams

    if args.commonroad is not None:  # the nodes build their scenario from a name or the ad-hoc flags, not from a file
        raise ParamError("--commonroad is not supported by moose launch: the nodes take the scenario as a name or "
                         "ad-hoc flags; run it with moose simulate --commonroad")
    scenario = scenario_from_args(args)
    common = {f.name for f in dataclasses.fields(NodeParams)}  # every node's own (lockstep_nodes, …): the launcher's
    scenario_fields = [f.name for f in dataclasses.fields(ScenarioParams) if f.name not in common]
    params = {k: getattr(args, k) for k in scenario_fields if getattr(args, k) is not None}
    params.update({f"can_{k}": getattr(args, f"can_{k}") for k in ("interface", "channel", "port")
                   if getattr(args, f"can_{k}") is not None})
    if args.mu_estimate is not None:  # the friction every node assumes: one value for the whole graph
        params["planning.mu_estimate"] = args.mu_estimate
    if args.timing is not None:  # the profile's delays for every node (compensate as configured)
        from moose.timing import profile

        chosen = profile(args.timing)
        params.update({f"timing.{k}": getattr(chosen, k) for k in ("sensor_delay_s", "planning_delay_s",
                                                                      "command_delay_s")})
    for key, value in parse_settings(args.set).items():
        if "." not in key:
            raise ParamError(f"--set {key}={value!r} is invalid: expected GROUP.KEY=VALUE")
        params[key] = value
    planner = planner_mode(args.planner, args.config)
    json_path = check_output_file("--json", args.json)  # before the run: nothing is lost at its end
    faults = [Fault.parse(text) for text in args.fault]
    bag = None if args.no_bag else (check_output_dir("--bag", args.bag) if args.bag is not None
                                    else run_folder(scenario.name, planner) / "bag")
    try:
        summary = launch(scenario, params, graph=args.graph, planner=planner, seed=args.seed, params_file=args.config,
                         rate=args.rate, bag=bag, faults=faults, runtime=args.runtime, lockstep=args.lockstep,
                         foxglove=(args.foxglove_host, args.foxglove) if args.foxglove is not None else None)
    except BagError as exc:
        raise ParamError(str(exc)) from None
    print(format_launch_summary(summary))
    print(f"runtime         {', '.join(f'{name} {rt}' for name, rt in summary['runtime'].items())}")
    failures = [summary["bag_error"]] if summary["bag_error"] else []
    if bag is not None and not failures:
        print(f"bag             {bag}")
    if json_path is not None:
        text = json.dumps(summary, indent=2, allow_nan=False) + "\n"
        failure = write_output("--json", json_path, lambda tmp: tmp.write_text(text, encoding="utf-8"))
        failures += [failure] if failure else []
    if failures:
        raise OutputError("; ".join(failures))
    return int(summary["exit_status"])


def format_launch_summary(summary: dict[str, Any]) -> str:
    """The summary of ``moose simulate`` (without odometry: the verdict alone), and what only the
    graph has: each node's end, the incidents, the real-time factor and the exit status."""
    if summary["odom_samples"]:
        lines = [format_summary(summary)]  # the verdict first, as moose simulate prints it
    else:
        lines = [f"outcome         {summary['outcome'].upper()}: {summary['reason']}",
                 "odometry        none: nothing to judge (incomplete)"]
    lines.append("nodes           " + ", ".join(f"{name} {end} ({summary['node_exits'].get(name)})"
                                                for name, end in summary["node_status"].items()))
    rtf = summary["real_time_factor"]
    achieved = "n/a" if rtf["achieved"] is None else f"{rtf['achieved']:.2f}"
    requested = "--lockstep" if rtf["requested"] is None else f"--rate {rtf['requested']:g}"
    lines.append(f"real time       {requested}, achieved {achieved}")
    misses = {n: c for n, c in summary["deadline_misses"].items() if c}
    lines.append(f"deadline misses {misses or 'none'}")
    lines.append(f"incidents       {len(summary['incidents'])}"
                 + (" (degraded)" if summary["degraded"] else ""))
    for incident in summary["incidents"]:
        t = "     " if incident["t"] is None else f"{incident['t']:5.2f}"
        more = f" (+{incident['repeats']} more)" if incident["repeats"] else ""
        lines.append(f"  {t} s  {incident['node']:<18} {incident['kind']:<16} {incident['message']}{more}")
    lines.append(f"exit status     {summary['exit_status']}")
    return "\n".join(lines)
