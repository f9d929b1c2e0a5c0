"""``moose launch [GRAPH]``: run the whole node graph as separate processes, summarised like ``moose simulate``."""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from moose.cli.common import DEFAULT_SCENARIO, add_scenario_arguments, positive_float, run_folder, scenario_from_args
from moose.cli.simulate import format_summary

from ..graph import GRAPHS


def add_subparser(subparsers: Any) -> None:
    launch = subparsers.add_parser("launch", help="run the whole node graph as separate processes")
    launch.add_argument("graph", nargs="?", default="full", choices=list(GRAPHS),
                        help="full (simulator on topics), car (CAN bridge, no simulator) or can (both over the DBC)")
    launch.add_argument("--can-interface", default="udp_multicast", choices=["udp_multicast", "socketcan", "virtual"])
    launch.add_argument("--can-channel", default="239.74.163.2", help="multicast group / socketcan device")
    launch.add_argument("--can-port", type=int, default=43113, help="UDP port of the udp_multicast bus")
    add_scenario_arguments(launch)
    launch.add_argument("--rate", type=positive_float, default=1.0, help="simulated seconds per wall-clock second")
    launch.add_argument("--json", help="write the summary as JSON to this path")
    launch.add_argument("--bag", help="record every topic into this bag directory (default: a new folder under runs/)")
    launch.add_argument("--no-bag", action="store_true", help="do not record a bag")
    launch.set_defaults(func=cmd_launch)


def cmd_launch(args: argparse.Namespace) -> int:
    from ..launch import launch

    scenario = scenario_from_args(args)
    if args.speed is not None:
        params = {"speed": args.speed, "tau": args.tau, "obstacle_half_width": args.obstacle_half_width,
                  "obstacle_length": args.obstacle_length}
    else:
        params = {"scenario": args.scenario or DEFAULT_SCENARIO}
    params.update({k: v for k, v in (("duration", args.duration), ("mu", args.mu)) if v is not None})
    bag = None if args.no_bag else (Path(args.bag) if args.bag else run_folder(scenario.name, args.planner or "combined") / "bag")
    summary = launch(scenario, params, graph=args.graph, planner=args.planner or "combined", seed=args.seed,
                     params_file=args.config, rate=args.rate, bag=bag,
                     can_params={"can_interface": args.can_interface, "can_channel": args.can_channel,
                                 "can_port": args.can_port})
    print(format_summary(summary))
    print(f"node exits      {summary['node_exits']}")
    if bag is not None:
        print(f"bag             {bag}")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    return 0
