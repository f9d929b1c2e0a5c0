"""``moose bag``: record, play, inspect, export, view and re-plan ROS 2 bags (MCAP).

Reading commands (info, play, export, replan, view) deliver everything they can read — a damaged chunk is
skipped, a truncated or unfinished recording is read to its end — then report every message they could not
read on stderr (``moose: warning: …``) and exit with status 1 (:data:`moose.verdict.EXIT_FAILED`); a topic
the bag does not have, a topic of the graph with another type, or an unusable output path is an error (status
2) before anything is done.  ``record`` whose bag cannot be written any more (a full disk) stops recording and
exits with status 5 (:data:`moose.verdict.EXIT_OUTPUT`); the bag holds what was recorded up to then.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any, Callable

from moose.cli.common import check_output_file, plot_suffixes, positive_float, run_folder, write_output
from moose.files import OutputError
from moose.params import ParamError
from moose.schema import PLANNER_MODES
from moose.verdict import EXIT_CLEAR, EXIT_FAILED, EXIT_INCOMPLETE

from ..lockstep import STUCK_TIMEOUT


def add_subparser(subparsers: Any) -> None:
    bag = subparsers.add_parser("bag", help="record, play, inspect, export and re-plan ROS 2 bags (MCAP)")
    bag_sub = bag.add_subparsers(dest="bag_command", required=True)
    record = bag_sub.add_parser("record", help="record topics of the running graph")
    record.add_argument("-o", "--output", help="bag directory to create")
    record.add_argument("--topics", nargs="+", help="topics to record")
    record.add_argument("--all", action="store_true", help="record every topic of the graph (default)")
    record.add_argument("--duration", type=positive_float, help="stop after this many seconds")
    play = bag_sub.add_parser("play", help="publish a bag into the graph with its original timing, or in lockstep "
                              "with the nodes it drives")
    play.add_argument("path")
    play.add_argument("--rate", type=positive_float, help="scale the original timing (default 1: real time)")
    play.add_argument("--topics", nargs="+")
    play.add_argument("--loop", action="store_true")
    play.add_argument("--start", type=float, default=0.0, help="skip this many seconds of the bag")
    play.add_argument("--clock", action="store_true", help="publish /clock from the bag's timestamps")
    play.add_argument("--lockstep", nargs="+", metavar="NODE",
                      help="replay tick by tick into these nodes, started with lockstep_nodes = [vehicle_simulator, "
                      "NODE ...]: the player takes the simulator's place and publishes the next tick once every NODE "
                      "has reported the last (paced by the nodes, not the clock; docs/bags.md)")
    play.add_argument("--lockstep-timeout", type=float, metavar="SECONDS",
                      help=f"with --lockstep: give up when a node has not reported a tick (or the nodes have not "
                      f"connected) after this many seconds, exit status 3 (default {STUCK_TIMEOUT:g})")
    info = bag_sub.add_parser("info", help="topics, types, counts, rates, duration")
    info.add_argument("path")
    export = bag_sub.add_parser("export", help="export topics to CSV or Parquet (one file per topic), or the run as a "
                                "CommonRoad scenario (commonroad.xml)")
    export.add_argument("--format", choices=["csv", "parquet", "commonroad"], default="csv")
    export.add_argument("path")
    export.add_argument("-o", "--output", required=True, help="output folder")
    export.add_argument("--topics", nargs="+")
    replan = bag_sub.add_parser("replan", help="run the planners open-loop on a bag's recorded state and threats")
    replan.add_argument("path")
    replan.add_argument("--planner", choices=PLANNER_MODES, help="planner mode (default: the run's)")
    replan.add_argument("--params", help="ROS 2 parameter file with the parameters to judge (default: the run's, "
                        "kept in the bag)")
    replan.add_argument("--v-des", type=positive_float, help="desired speed (default: the run's scenario)")
    replan.add_argument("--plot", help="write recorded vs re-computed references (PNG)")
    view = bag_sub.add_parser("view", help="bird's-eye view: path, danger zone, predicted paths (PNG)")
    view.add_argument("path")
    view.add_argument("-o", "--output", required=True, help="PNG to write")
    for parser_ in (record, play, info, export, replan, view):
        parser_.set_defaults(func=cmd_bag)


def cmd_bag(args: argparse.Namespace) -> int:
    from .. import bag

    report = bag.ReadReport(getattr(args, "path", ""))
    try:
        if args.bag_command == "info":
            info = bag.bag_info(args.path, report)
            print(f"bag       {info['path']}\nduration  {info['duration_s']:.3f} s\nmessages  {info['messages']}")
            for topic, e in info["topics"].items():
                print(f"  {topic:<28} {e['type']:<36} {e['count']:>7}  {e['rate_hz']:8.2f} Hz")
            for type_name in info["registered_types"]:
                print(f"  (decoded with the bag's own definition: {type_name})")
        elif args.bag_command == "export" and args.format == "commonroad":
            from ..bag.commonroad import export_commonroad

            if args.topics:
                raise ParamError("--topics does not apply to --format commonroad (it exports the run)")
            print(export_commonroad(args.path, args.output, report))
        elif args.bag_command == "export":
            for path in bag.export(args.path, args.output, args.topics, args.format, report):
                print(path)
        elif args.bag_command == "replan":
            from moose.config import load_config

            plot = check_output_file("--plot", args.plot, plot_suffixes()) if args.plot is not None else None
            config = load_config(args.params, "moose bag replan") if args.params else None
            result = bag.replan(args.path, config, args.planner, args.v_des, report)
            summary = result["summary"]
            print({"given": f"parameters      {args.params}",
                   "bag": f"parameters      the run's (bag): scenario {summary['scenario']}, "
                          f"road μ {summary['road_mu']}",
                   "default": "parameters      default config/moose.yaml (the bag has no run parameters)"}[
                       summary["parameters"]])
            print("  t (s)   w rec / new    v̇_Y rec / new (m/s²)   δ* rec / new (rad)   MPC status rec / new")
            for r in result["rows"]:
                print(f"{r['t']:7.2f}   {r['recorded_weight']:5.2f} / {r['weight']:5.2f}   "
                      f"{r['recorded_ay']:8.3f} / {r['ay']:8.3f}      "
                      f"{r['recorded_delta']:6.3f} / {r['delta']:6.3f}     "
                      f"{r['recorded_mpc_status'] or '-'} / {r['mpc_status'] or '-'}")
            print(json.dumps(summary, indent=2, allow_nan=False))
            if plot is not None:
                _write_figure("--plot", plot, lambda tmp: bag.plot_replan(result["rows"], tmp))
        elif args.bag_command == "view":
            out = check_output_file("-o", args.output, plot_suffixes())
            assert out is not None  # -o is required
            _write_figure("-o", out, lambda tmp: bag.plot_birdseye(args.path, tmp, report=report))
        elif args.bag_command == "record":
            return _record(bag, args)
        elif args.bag_command == "play":
            from ..bag.play import check_lockstep
            from ..runtime import DdsNode

            timeout = STUCK_TIMEOUT if args.lockstep_timeout is None else args.lockstep_timeout
            if args.lockstep:
                check_lockstep(args.lockstep, args.rate, args.loop, timeout)
            elif args.lockstep_timeout is not None:
                raise ParamError(f"--lockstep-timeout {args.lockstep_timeout:g} applies only with --lockstep")
            node = DdsNode("moose_bag_play")
            try:
                sent = bag.play(args.path, node, rate=args.rate, topics=args.topics, loop=args.loop, start=args.start,
                                clock=args.clock, report=report, lockstep=args.lockstep or (), timeout=timeout)
            except bag.LockstepStuck as exc:
                print(f"played {exc.sent} messages")
                print(f"moose: error: {exc}", file=sys.stderr)
                return EXIT_INCOMPLETE
            finally:
                node.shutdown()
            print(f"played {sent} messages")
    except bag.BagError as exc:
        raise ParamError(str(exc)) from None
    for line in report.losses():
        print(f"moose: warning: {line}", file=sys.stderr)
    return EXIT_CLEAR if report.complete else EXIT_FAILED


def _write_figure(flag: str, path: Path, draw: Callable[[Path], Any]) -> None:
    """Draw the figure ``path`` of a reading command, whole or not at all; a full disk is an
    :class:`~moose.files.OutputError` (exit status 5) after what was printed."""
    failure = write_output(flag, path, draw)
    if failure is not None:
        raise OutputError(failure)
    print(f"figure {path}")


def _record(bag: Any, args: argparse.Namespace) -> int:
    import signal
    import threading
    import time

    from ..runtime import DdsNode

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
    if recorder.error is not None:
        raise OutputError(recorder.error)
    print(f"recorded {dict(recorder.writer.counts)}")
    return 0
