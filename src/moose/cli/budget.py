"""``moose budget``: the latency budget of the paper's nine cases on the command and the planning path
(:mod:`moose.budget`), with and without delay compensation.

Prints the table; ``--figure PNG`` draws clearance against added latency, ``--write FILE`` regenerates the generated
blocks FILE holds (docs/architecture.md: ``budget``; README.md: ``budget-summary``), ``--json`` writes every point.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path
from typing import Any

from ..params import ParamError
from .common import add_timing_argument, check_output_file, plot_suffixes, positive_float, run_config

GENERATED = ("budget", "budget-summary")
"""The generated blocks a document may hold."""


def add_subparser(subparsers: Any) -> None:
    parser = subparsers.add_parser("budget", help="the latency budget of the paper's cases (command and planning path)")
    parser.add_argument("--config", help="ROS 2 parameter file (default config/moose.yaml)")
    parser.add_argument("--set", action="append", default=[], metavar="GROUP.KEY=VALUE",
                        help="change one parameter of the configuration (repeatable)")
    add_timing_argument(parser)
    parser.add_argument("--case", action="append", metavar="SCENARIO",
                        help="a paper case (repeatable; default the nine of Figs. 5-7)")
    parser.add_argument("--step-ms", type=positive_float, default=10.0,
                        help="resolution: the step of the added latency, a whole number of motion ticks (default 10)")
    parser.add_argument("--max-ms", type=positive_float, default=500.0, help="largest added latency (default 500)")
    parser.add_argument("--workers", type=int, help="worker processes (default: the number of cores)")
    parser.add_argument("--figure", help="write the figure (PNG) to this path")
    parser.add_argument("--write", metavar="MARKDOWN", action="append",
                        help="regenerate the generated blocks this file holds (budget: docs/architecture.md; "
                             "budget-summary: README.md); may be given more than once")
    parser.add_argument("--json", help="write every point as JSON to this path")
    parser.set_defaults(func=cmd_budget)


def cmd_budget(args: argparse.Namespace) -> int:
    from ..budget import budgets, latencies, plot_budget, render_summary, render_table, run_points
    from ..reproduce import DURATION, EXTREME, NINE, blocks_in, update_document
    from ..scenario import load_scenario

    config = run_config(args, "moose budget")
    cases = tuple(args.case or NINE)
    for case in cases:
        load_scenario(case)  # an unknown name is refused before anything runs
    step = args.step_ms / 1e3
    ticks = step / config.motion_period
    if abs(ticks - round(ticks)) > 1e-6:
        raise ParamError(f"--step-ms = {args.step_ms!r} is invalid: expected a whole number of motion-control periods "
                         f"({config.motion_period * 1e3:g} ms)")
    if args.max_ms < args.step_ms:
        raise ParamError(f"--max-ms = {args.max_ms!r} is invalid: expected at least --step-ms = {args.step_ms!r}")
    if args.workers is not None and args.workers < 1:
        raise ParamError(f"--workers = {args.workers!r} is invalid: expected at least 1")
    writes = [Path(p) for p in args.write or []]
    for path in writes:
        if not path.is_file():
            raise ParamError(f"--write = {str(path)!r} is invalid: no such file")
        if not blocks_in(path, GENERATED):
            raise ParamError(f"--write = {str(path)!r} is invalid: it holds none of the generated blocks "
                             f"({', '.join(GENERATED)})")
        if "budget-summary" in blocks_in(path, GENERATED) and EXTREME not in cases:
            raise ParamError(f"--write = {str(path)!r}: its budget-summary is about {EXTREME}, which --case leaves out")
    figure = check_output_file("--figure", args.figure, plot_suffixes())
    json_path = check_output_file("--json", args.json)

    def progress(done: int, total: int) -> None:
        if done % 50 == 0 or done == total:
            print(f"  {done}/{total} runs", file=sys.stderr, flush=True)

    points = run_points(config, cases, latencies(args.max_ms / 1e3, step), DURATION,
                        workers=args.workers or os.cpu_count() or 1, progress=progress)
    found = budgets(points)
    table = render_table(found, config, step)
    print(table)
    if json_path is not None:
        json_path.write_text(json.dumps([p.__dict__ for p in points], indent=1, allow_nan=False) + "\n",
                             encoding="utf-8")
    if figure is not None:
        print(f"figure          {plot_budget(points, found, figure)}")
    rendered = {"budget": table}
    if EXTREME in cases:
        rendered["budget-summary"] = render_summary(found, points, config, EXTREME, step)
    for path in writes:
        names = blocks_in(path, GENERATED)
        update_document(path, {name: rendered[name] for name in names})
        print(f"wrote {', '.join(names)} of {path}")
    return 0
