"""``moose simulate``: one moose test in lockstep (a scenario file or an ad-hoc test).

Prints the summary and optionally writes JSON and the figure.  The run is recorded as a ROS 2 bag
by the recorder plugin (entry point group ``moose.recorders``, provided by moose_ros) unless
``--no-bag``; without a recorder installed the command says so and records nothing.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any, Callable, Optional

from ..params import ParamError
from .common import add_scenario_arguments, run_folder, scenario_from_args
from .plugins import recorder


def add_subparser(subparsers: Any) -> None:
    simulate = subparsers.add_parser("simulate", help="run one moose test in lockstep")
    add_scenario_arguments(simulate)
    simulate.add_argument("--json", help="write the summary as JSON to this path")
    simulate.add_argument("--plot", help="write the paper-style figure (PNG) to this path")
    simulate.add_argument("--bag", help="record the run into this bag directory (default: a new folder under runs/)")
    simulate.add_argument("--no-bag", action="store_true", help="do not record a bag")
    simulate.add_argument("--set", action="append", default=[], metavar="GROUP.KEY=VALUE",
                          help="change one parameter of the configuration, e.g. planning.N_p=20 (repeatable)")
    simulate.set_defaults(func=cmd_simulate)


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


def parse_settings(items: list[str]) -> dict[str, Any]:
    """``GROUP.KEY=VALUE`` items as a mapping (values are YAML scalars: numbers, true/false, names)."""
    import yaml

    settings: dict[str, Any] = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep or not key.strip():
            raise ParamError(f"--set {item!r} is invalid: expected GROUP.KEY=VALUE")
        try:
            settings[key.strip()] = yaml.safe_load(text)
        except yaml.YAMLError:
            settings[key.strip()] = text
    return settings


def cmd_simulate(args: argparse.Namespace) -> int:
    from ..config import load_config, with_overrides
    from ..metrics import summarize
    from ..plots import plot_result
    from ..simulation import simulate

    record = bag_recorder(args)
    scenario = scenario_from_args(args)
    config = load_config(args.config)
    if args.set:
        config = with_overrides(config, parse_settings(args.set))
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
    if record is not None:
        path = Path(args.bag) if args.bag else run_folder(scenario.name, result.planner) / "bag"
        record(result, path)
        print(f"bag             {path}")
    return 0

