"""``moose simulate``: one moose test in lockstep (a scenario file or an ad-hoc test).

Prints the summary (the verdict first) and optionally writes JSON and the figure.  The run is recorded as a
ROS 2 bag by the recorder plugin (entry point group ``moose.recorders``, provided by moose_ros) unless
``--no-bag``; without a recorder installed the command says so and records nothing.  Every output path is
checked before the run starts; one that cannot be written after it (a full disk) is reported after the
verdict, the others are still written.  Exit status: 0 ``clear``, 1 a failure outcome (``collision``,
``left_field``, ``lost_control``, ``stopped_short``), 3 ``incomplete``, 2 bad input, 5 an output could not
be written (the verdict is printed above the error), 130 Ctrl-C (:data:`moose.verdict.OUTCOME_EXIT`).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any, Callable, Optional

from ..files import OutputError
from ..params import ParamError
from ..scenario.args import scenario_from_args
from ..verdict import exit_status
from .common import (
    INTERRUPTS,
    add_scenario_arguments,
    add_timing_argument,
    check_output_dir,
    check_output_file,
    plot_suffixes,
    run_config,
    run_folder,
    write_output,
)
from .plugins import recorder


def add_subparser(subparsers: Any) -> None:
    simulate = subparsers.add_parser("simulate", help="run one moose test in lockstep")
    add_scenario_arguments(simulate)
    simulate.add_argument("--json", help="write the summary as JSON to this path")
    simulate.add_argument("--plot", help="write the paper-style figure (PNG) to this path")
    simulate.add_argument("--bag", help="record the run into this bag directory (default: a new folder under runs/)")
    simulate.add_argument("--no-bag", action="store_true", help="do not record a bag")
    simulate.add_argument("--commonroad-out", metavar="FILE.xml",
                          help="write the run as a CommonRoad scenario (road, obstacle, planning problem, ego path)")
    simulate.add_argument("--criticality", action="store_true",
                          help="add commonroad-crime's TTC, TTB, TTS, TTK, TTR to the summary (a few seconds)")
    simulate.add_argument("--set", action="append", default=[], metavar="GROUP.KEY=VALUE",
                          help="change one parameter of the configuration, e.g. planning.N_p=20 (repeatable)")
    add_timing_argument(simulate)
    simulate.set_defaults(func=cmd_simulate)


def format_summary(summary: dict[str, Any]) -> str:
    """Human-readable lines of a run summary."""
    from ..verdict import changed_limits

    solve = summary["mpc_solve_ms"]
    changed = changed_limits(summary["verdict_limits"])
    judged = f" under NON-DEFAULT verdict limits ({changed})" if changed else ""
    lines = [
        f"scenario        {summary['scenario']}  (planner {summary['planner']}, seed {summary['seed']})",
        f"outcome         {summary['outcome'].upper()}{judged}: {summary['reason']}",
        f"threat          tau = {_fmt(summary['tau_s'])} s, nu = {_fmt(summary['nu'])}"
        f" (paper {_fmt(summary['paper_nu'])}), w = {_fmt(summary['w_m'])} m",
        f"min clearance   {_fmt(summary['min_clearance_m'], '.2f')} m",
        f"max |delta|     {_fmt(summary['max_abs_steer_rad'], '.3f')} rad",
        f"max |y - y0|    {_fmt(summary['max_lateral_offset_m'], '.2f')} m"
        f" (final {_fmt(summary['final_lateral_offset_m'], '+.2f')} m)",
        f"speed range     {_fmt(summary['min_speed_mps'], '.2f')} .. {_fmt(summary['max_speed_mps'], '.2f')} m/s",
        f"MPC solves      {solve['count']}  median {_fmt(solve['median'])} ms, p95 {_fmt(solve['p95'])} ms,"
        f" max {_fmt(solve['max'])} ms  statuses {summary['mpc_status_counts']}",
        f"mean w_MPC      {_fmt(summary['mean_weight_mpc'])} (over steps with a threat)",
        f"timing          {format_timing(summary['timing'])}",
    ]
    independent = summary.get("commonroad_verdict")
    if independent is not None:
        found = (f"footprint {'touches' if independent['collision'] else 'clear of'} the obstacle, "
                 f"{'stays on' if independent['road_compliant'] else 'leaves'} the road")
        how = "agrees" if independent["agrees"] else "differs: " + "; ".join(independent["differences"])
        lines.append(f"CommonRoad      {found} ({how})")
    measures = summary.get("criticality")
    if measures is not None:
        lines.append("criticality     " + ", ".join(f"{k.split('_')[0].upper()} {_fmt(v)}" for k, v in measures.items()
                                                    if k.endswith("_s")))
    return "\n".join(lines)


def format_timing(timing: dict[str, Any]) -> str:
    """A summary's timing in one line: the profile and every delay in ms."""
    delays = ", ".join(f"{name} {timing[f'{name}_delay_s'] * 1e3:.0f} ms" for name in ("sensor", "planning", "command"))
    return f"{timing['profile']} ({delays}; compensation {'on' if timing['compensate'] else 'off'})"


def _fmt(value: Any, spec: str = ".3g") -> str:
    return "n/a" if value is None else format(value, spec)


def bag_recorder(args: argparse.Namespace) -> Optional[Callable[[Any, Path], Any]]:
    """The installed bag recorder, ``None`` with ``--no-bag``; without one, ``--bag`` is an error and the
    default only a note (on stderr), both given before the run."""
    if args.no_bag:
        return None
    record = recorder()
    if record is None:
        missing = "the bag recorder comes with the moose_ros package (pip install ros2_ws/src/moose_ros)"
        if args.bag:
            raise ParamError(f"--bag {args.bag!r}: {missing}")
        print(f"moose: note: no bag recorded: {missing}; --no-bag silences this note", file=sys.stderr)
    return record


def _write(failures: list[str], label: str, flag: str, path: Path, write: Callable[[Path], Any]) -> None:
    """Write one output of the finished run (:func:`~moose.cli.common.write_output`) and say where it went, or
    keep why it could not be written in ``failures``."""
    failure = write_output(flag, path, write)
    if failure is None:
        print(f"{label:<16}{path}")
    else:
        failures.append(failure)


def cmd_simulate(args: argparse.Namespace) -> int:
    from ..metrics import summarize
    from ..plots import plot_result
    from ..simulation import simulate

    record = bag_recorder(args)
    config = run_config(args, "moose simulate")
    scenario = scenario_from_args(args, config.vehicle)
    if args.commonroad_out is not None or args.criticality:
        from ..commonroad import require

        require("--commonroad-out" if args.commonroad_out is not None else "--criticality")
    # every output is checked before the run, so none of them is lost at its end
    json_path = check_output_file("--json", args.json)
    commonroad_path = check_output_file("--commonroad-out", args.commonroad_out, ("xml",))
    plot_path = check_output_file("--plot", args.plot, plot_suffixes()) if args.plot is not None else None
    bag_path = check_output_dir("--bag", args.bag) if record is not None else None
    result = simulate(config, scenario, planner=args.planner, seed=args.seed)
    INTERRUPTS.check()  # an interrupted run is not reported as one that ended
    summary = summarize(result, criticality=args.criticality)
    print(format_summary(summary))
    failures: list[str] = []  # an output that fails now (a full disk) is reported after the verdict
    if commonroad_path is not None:
        from ..commonroad.scenario import write_run

        _write(failures, "commonroad", "--commonroad-out", commonroad_path, lambda tmp: write_run(result, tmp))
    if json_path is not None:
        text = json.dumps(summary, indent=2, allow_nan=False) + "\n"
        _write(failures, "summary", "--json", json_path, lambda tmp: tmp.write_text(text, encoding="utf-8"))
    if plot_path is not None:
        _write(failures, "figure", "--plot", plot_path, lambda tmp: plot_result([result], tmp))
    if record is not None:
        path = bag_path if bag_path is not None else run_folder(scenario.name, result.planner) / "bag"
        try:
            record(result, path)
            print(f"bag             {path}")
        except OutputError as exc:
            failures.append(str(exc))
    if failures:
        raise OutputError("; ".join(failures))
    return exit_status(summary["outcome"])

