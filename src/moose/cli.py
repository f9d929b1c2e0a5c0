"""The ``moose`` command.

``moose simulate`` runs one moose test in lockstep (a scenario file or an
ad-hoc test), prints the summary and optionally writes JSON and the figure.
Bad input ends with ``moose: error: …`` naming the field and the value, and a
non-zero exit status.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any, Callable, Sequence

from .params import ParamError

DEFAULT_SCENARIO = "paper_v7_tau1.4"
"""The paper's extreme case (7 m/s, τ = 1.4 s, ν ≈ 0.95): the main job."""


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not value > 0.0:
        raise argparse.ArgumentTypeError(f"{text!r} must be positive")
    return value


def add_scenario_arguments(parser: argparse.ArgumentParser) -> None:
    """Scenario selection shared by ``simulate`` and ``launch``."""
    group = parser.add_argument_group("scenario (a file or an ad-hoc moose test)")
    group.add_argument("--scenario", help=f"name in config/scenarios or a YAML path (default {DEFAULT_SCENARIO})")
    group.add_argument("--speed", type=_positive_float, help="ad-hoc test: speed at detection and desired speed (m/s)")
    group.add_argument("--tau", type=_positive_float, help="ad-hoc test: time to collision at appearance (s)")
    group.add_argument("--obstacle-half-width", type=_positive_float, help="ad-hoc test: danger-zone half width (m)")
    group.add_argument("--obstacle-length", type=_positive_float, default=2.0, help="ad-hoc test: length (m)")
    group.add_argument("--duration", type=_positive_float, help="simulated seconds after the obstacle appears")
    group.add_argument("--config", help="ROS 2 parameter file (default config/moose.yaml)")
    group.add_argument("--planner", choices=["combined", "mpc", "msf"], help="planner driving the car")
    group.add_argument("--mu", type=_positive_float, help="friction coefficient of the plant")
    group.add_argument("--seed", type=int, default=0, help="seed of the sensor noise")


def scenario_from_args(args: argparse.Namespace) -> Any:
    """The scenario named by the arguments (file, or ad-hoc flags)."""
    import dataclasses

    from .scenario import adhoc_scenario, load_scenario

    adhoc = [args.speed, args.tau, args.obstacle_half_width]
    if any(v is not None for v in adhoc):
        if args.scenario:
            raise ParamError("--scenario cannot be combined with the ad-hoc flags --speed/--tau/--obstacle-half-width")
        if any(v is None for v in adhoc):
            raise ParamError("an ad-hoc moose test needs --speed, --tau and --obstacle-half-width")
        scenario = adhoc_scenario(args.speed, args.tau, args.obstacle_half_width, args.obstacle_length)
    else:
        scenario = load_scenario(args.scenario or DEFAULT_SCENARIO)
    changes: dict[str, Any] = {}
    if args.duration is not None:
        changes["duration"] = args.duration
    if args.mu is not None:
        changes["mu"] = args.mu
    return dataclasses.replace(scenario, **changes) if changes else scenario


def format_summary(summary: dict[str, Any]) -> str:
    """Human-readable lines of a run summary."""
    solve = summary["mpc_solve_ms"]
    lines = [
        f"scenario        {summary['scenario']}  (planner {summary['planner']}, seed {summary['seed']})",
        f"threat          tau = {_fmt(summary['tau_s'])} s, nu = {_fmt(summary['nu'])}"
        f" (paper {_fmt(summary['paper_nu'])}), w = {_fmt(summary['w_m'])} m",
        f"outcome         {'COLLISION' if summary['collided'] else 'collision-free'}, "
        f"{'LEFT THE FIELD' if summary['left_field'] else 'inside the field'}",
        f"min clearance   {summary['min_clearance_m']:.2f} m",
        f"max |delta|     {summary['max_abs_steer_rad']:.3f} rad",
        f"max |y - y0|    {summary['max_lateral_offset_m']:.2f} m (final {summary['final_lateral_offset_m']:+.2f} m)",
        f"speed range     {summary['min_speed_mps']:.2f} .. {summary['max_speed_mps']:.2f} m/s",
        f"MPC solves      {solve['count']}  median {_fmt(solve['median'])} ms, p95 {_fmt(solve['p95'])} ms,"
        f" max {_fmt(solve['max'])} ms  statuses {summary['mpc_status_counts']}",
        f"mean w_MPC      {_fmt(summary['mean_weight_mpc'])} (over steps with a threat)",
    ]
    return "\n".join(lines)


def _fmt(value: Any) -> str:
    return "n/a" if value is None else f"{value:.3g}"


def cmd_simulate(args: argparse.Namespace) -> int:
    from .config import load_config
    from .metrics import summarize
    from .plots import plot_result
    from .simulation import simulate

    scenario = scenario_from_args(args)
    config = load_config(args.config)
    result = simulate(config, scenario, planner=args.planner, seed=args.seed)
    summary = summarize(result)
    print(format_summary(summary))
    if args.json:
        path = Path(args.json)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
        print(f"summary         {path}")
    if args.plot:
        print(f"figure          {plot_result([result], args.plot)}")
    if not args.no_bag:
        bag = _ros().bag
        path = Path(args.bag) if args.bag else run_folder(scenario.name, result.planner) / "bag"
        bag.record_result(result, path)
        print(f"bag             {path}")
    return 0


def run_folder(scenario: str, planner: str) -> Path:
    """A new folder under runs/ for this run's outputs."""
    import time

    stamp = time.strftime("%Y%m%d-%H%M%S")
    base = Path("runs") / f"{stamp}_{scenario}_{planner}"
    path, n = base, 1
    while path.exists():
        n += 1
        path = Path(f"{base}_{n}")
    return path


def _ros() -> Any:
    try:
        import moose_ros.bag
        import moose_ros.launch
        import moose_ros.nodes
    except ImportError as exc:
        raise ParamError(f"the node graph needs the moose_ros package (pip install -e ros2_ws/src/moose_ros): {exc}") from None
    return moose_ros


def cmd_node(args: argparse.Namespace) -> int:
    ros = _ros()
    argv = (["--params", args.params] if args.params else []) + [a for p in args.param for a in ("--param", p)]
    return int(ros.nodes.run(args.name, argv))


def cmd_launch(args: argparse.Namespace) -> int:
    ros = _ros()
    scenario = scenario_from_args(args)
    if args.speed is not None:
        params = {"speed": args.speed, "tau": args.tau, "obstacle_half_width": args.obstacle_half_width,
                  "obstacle_length": args.obstacle_length}
    else:
        params = {"scenario": args.scenario or DEFAULT_SCENARIO}
    params.update({k: v for k, v in (("duration", args.duration), ("mu", args.mu)) if v is not None})
    bag = None if args.no_bag else (Path(args.bag) if args.bag else run_folder(scenario.name, args.planner or "combined") / "bag")
    summary = ros.launch.launch(scenario, params, graph=args.graph, planner=args.planner or "combined", seed=args.seed,
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


def cmd_bag(args: argparse.Namespace) -> int:
    bag = _ros().bag
    try:
        if args.bag_command == "info":
            info = bag.bag_info(args.path)
            print(f"bag       {info['path']}\nduration  {info['duration_s']:.3f} s\nmessages  {info['messages']}")
            for topic, e in info["topics"].items():
                print(f"  {topic:<28} {e['type']:<36} {e['count']:>7}  {e['rate_hz']:8.2f} Hz")
        elif args.bag_command == "export":
            for path in bag.export(args.path, args.output, args.topics, args.format):
                print(path)
        elif args.bag_command == "replan":
            from .config import load_config

            result = bag.replan(args.path, load_config(args.params), args.planner, args.v_des)
            summary = result["summary"]
            print("  t (s)   w rec / new    v̇_Y rec / new (m/s²)   δ* rec / new (rad)   MPC status rec / new")
            for r in result["rows"]:
                print(f"{r['t']:7.2f}   {r['recorded_weight']:5.2f} / {r['weight']:5.2f}   {r['recorded_ay']:8.3f} / {r['ay']:8.3f}"
                      f"      {r['recorded_delta']:6.3f} / {r['delta']:6.3f}     {r['recorded_mpc_status'] or '-'} / {r['mpc_status'] or '-'}")
            print(json.dumps(summary, indent=2))
            if args.plot:
                print(f"figure {bag.plot_replan(result['rows'], args.plot)}")
        elif args.bag_command == "record":
            return _record(bag, args)
        elif args.bag_command == "play":
            from moose_ros.runtime import DdsNode

            node = DdsNode("moose_bag_play")
            sent = bag.play(args.path, node, rate=args.rate, topics=args.topics, loop=args.loop, start=args.start,
                            clock=args.clock)
            print(f"played {sent} messages")
    except bag.BagError as exc:
        raise ParamError(str(exc)) from None
    return 0


def _record(bag: Any, args: argparse.Namespace) -> int:
    import signal
    import threading
    import time

    from moose_ros.runtime import DdsNode

    node = DdsNode("moose_bag_record")
    path = Path(args.output) if args.output else run_folder("record", "graph") / "bag"
    recorder = bag.Recorder(node, path, None if args.all else args.topics)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    print(f"recording into {path} (Ctrl-C to stop)", flush=True)
    start = time.monotonic()
    try:
        while not stop.is_set() and (args.duration is None or time.monotonic() - start < args.duration):
            node.spin_once(0.05)
    finally:
        recorder.close()
    print(f"recorded {dict(recorder.writer.counts)}")
    return 0


def cmd_can(args: argparse.Namespace) -> int:
    from .canbus.bus import open_bus
    from .canbus.tools import dump, replay

    try:
        bus = open_bus(args.interface, args.channel, port=args.port)
    except ValueError as exc:
        raise ParamError(str(exc)) from None
    try:
        if args.can_command == "dump":
            dump(bus, sys.stdout, count=args.count, duration=args.duration)
        else:
            try:
                print(f"sent {replay(args.file, bus, rate=args.rate)} frames")
            except FileNotFoundError as exc:
                raise ParamError(str(exc)) from None
    except KeyboardInterrupt:
        pass
    finally:
        bus.shutdown()
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="moose", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    simulate = sub.add_parser("simulate", help="run one moose test in lockstep")
    add_scenario_arguments(simulate)
    simulate.add_argument("--json", help="write the summary as JSON to this path")
    simulate.add_argument("--plot", help="write the paper-style figure (PNG) to this path")
    simulate.add_argument("--bag", help="record the run into this bag directory (default: a new folder under runs/)")
    simulate.add_argument("--no-bag", action="store_true", help="do not record a bag")
    simulate.set_defaults(handler=cmd_simulate)
    node = sub.add_parser("node", help="run one node of the graph (Cyclone DDS, or rclpy when installed)")
    node.add_argument("name", help="observer, obstacle_detector, mpc_planner, msf_planner, weight_fbl, "
                                   "motion_controller or vehicle_simulator")
    node.add_argument("--params", help="ROS 2 parameter file")
    node.add_argument("--param", action="append", default=[], help="parameter override key=value")
    node.set_defaults(handler=cmd_node)
    launch = sub.add_parser("launch", help="run the whole node graph as separate processes")
    launch.add_argument("graph", nargs="?", default="full", choices=["full", "car", "can"],
                        help="full (simulator on topics), car (CAN bridge, no simulator) or can (both over the DBC)")
    launch.add_argument("--can-interface", default="udp_multicast", choices=["udp_multicast", "socketcan", "virtual"])
    launch.add_argument("--can-channel", default="239.74.163.2", help="multicast group / socketcan device")
    launch.add_argument("--can-port", type=int, default=43113, help="UDP port of the udp_multicast bus")
    add_scenario_arguments(launch)
    launch.add_argument("--rate", type=_positive_float, default=1.0, help="simulated seconds per wall-clock second")
    launch.add_argument("--json", help="write the summary as JSON to this path")
    launch.add_argument("--bag", help="record every topic into this bag directory (default: a new folder under runs/)")
    launch.add_argument("--no-bag", action="store_true", help="do not record a bag")
    launch.set_defaults(handler=cmd_launch)
    bag = sub.add_parser("bag", help="record, play, inspect, export and re-plan ROS 2 bags (MCAP)")
    bag_sub = bag.add_subparsers(dest="bag_command", required=True)
    record = bag_sub.add_parser("record", help="record topics of the running graph")
    record.add_argument("-o", "--output", help="bag directory to create")
    record.add_argument("--topics", nargs="+", help="topics to record")
    record.add_argument("--all", action="store_true", help="record every topic of the graph (default)")
    record.add_argument("--duration", type=_positive_float, help="stop after this many seconds")
    play = bag_sub.add_parser("play", help="publish a bag into the graph with its original timing")
    play.add_argument("path")
    play.add_argument("--rate", type=_positive_float, default=1.0)
    play.add_argument("--topics", nargs="+")
    play.add_argument("--loop", action="store_true")
    play.add_argument("--start", type=float, default=0.0, help="skip this many seconds of the bag")
    play.add_argument("--clock", action="store_true", help="publish /clock from the bag's timestamps")
    info = bag_sub.add_parser("info", help="topics, types, counts, rates, duration")
    info.add_argument("path")
    export = bag_sub.add_parser("export", help="export topics to CSV or Parquet (one file per topic)")
    export.add_argument("--format", choices=["csv", "parquet"], default="csv")
    export.add_argument("path")
    export.add_argument("-o", "--output", required=True, help="output folder")
    export.add_argument("--topics", nargs="+")
    replan = bag_sub.add_parser("replan", help="run the planners open-loop on a bag's recorded state and threats")
    replan.add_argument("path")
    replan.add_argument("--planner", choices=["combined", "mpc", "msf"], default="combined")
    replan.add_argument("--params", help="ROS 2 parameter file with the parameters to judge")
    replan.add_argument("--v-des", type=_positive_float, help="desired speed (default: speed at the first estimate)")
    replan.add_argument("--plot", help="write recorded vs re-computed references (PNG)")
    for parser_ in (record, play, info, export, replan):
        parser_.set_defaults(handler=cmd_bag)
    can_parser = sub.add_parser("can", help="vehicle-bus tools (DBC config/kanon.dbc)")
    can_sub = can_parser.add_subparsers(dest="can_command", required=True)
    can_dump = can_sub.add_parser("dump", help="decode live frames with the DBC")
    can_dump.add_argument("--count", type=int, help="stop after this many frames")
    can_dump.add_argument("--duration", type=_positive_float, help="stop after this many seconds")
    can_replay = can_sub.add_parser("replay", help="send a python-can log (.asc, .blf, .log, ...) onto the bus")
    can_replay.add_argument("file")
    can_replay.add_argument("--rate", type=_positive_float, default=1.0)
    for parser_ in (can_dump, can_replay):
        parser_.add_argument("--interface", default="udp_multicast", help="socketcan, udp_multicast or virtual")
        parser_.add_argument("--channel", default="239.74.163.2", help="multicast group or socketcan device")
        parser_.add_argument("--port", type=int, default=43113, help="UDP port (udp_multicast)")
        parser_.set_defaults(handler=cmd_can)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    handler: Callable[[argparse.Namespace], int] = args.handler
    try:
        return handler(args)
    except ParamError as exc:
        print(f"moose: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
