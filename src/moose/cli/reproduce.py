"""``moose reproduce``: re-run the paper's cases with every planner and judge its claims (:mod:`moose.reproduce`).

Prints the claims table (``--variants``: also the table of the readings the paper leaves open); ``--write FILE``
regenerates the generated blocks FILE holds (docs/modelling.md: the calibration and the variants; docs/results.md:
the conditions, the results and the claims; README.md: the summary), ``--json`` writes the summary of every run made.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from ..params import ParamError
from .common import add_timing_argument, non_negative_int, planner_list, run_config


def add_subparser(subparsers: Any) -> None:
    parser = subparsers.add_parser("reproduce", help="re-run the paper's cases and judge its claims")
    parser.add_argument("--config", help="ROS 2 parameter file (default config/moose.yaml)")
    parser.add_argument("--seed", type=non_negative_int, default=0, help="seed of the sensor noise (an integer >= 0)")
    parser.add_argument("--variants", action="store_true",
                        help="also run and print the readings the paper leaves open, side by side (nine cases each)")
    parser.add_argument("--write", metavar="MARKDOWN", action="append",
                        help="regenerate the generated blocks this file holds (calibration, conditions, results, "
                             "claims, variants, summary: docs/modelling.md, docs/results.md, README.md); may be "
                             "given more than once")
    parser.add_argument("--json", help="write the summary of every run made as JSON to this path")
    parser.add_argument("--planner", metavar="P[,P...]", type=planner_list,
                        help="also run these planners (e.g. the baselines aeb,max_steer): rows of the results and of "
                             "--json, no claim; the paper's planners always run")
    parser.add_argument("--set", action="append", default=[], metavar="GROUP.KEY=VALUE",
                        help="change one parameter of the configuration, e.g. timing.compensate=true (repeatable)")
    add_timing_argument(parser)
    parser.set_defaults(func=cmd_reproduce)


GENERATED = ("calibration", "conditions", "results", "claims", "variants", "summary")
"""The generated blocks a document may hold."""


def cmd_reproduce(args: argparse.Namespace) -> int:
    from ..reproduce import (
        RunCache,
        blocks_in,
        claims,
        render_calibration,
        render_claims,
        render_conditions,
        render_results,
        render_summary,
        render_variants,
        result_runs,
        update_document,
        variant_rows,
    )

    writes = [Path(p) for p in args.write or []]
    for path in writes:
        if not path.is_file():
            raise ParamError(f"--write = {str(path)!r} is invalid: no such file")
        if not blocks_in(path, GENERATED):
            raise ParamError(f"--write = {str(path)!r} is invalid: it holds none of the generated blocks "
                             f"({', '.join(GENERATED)})")
    if args.json is not None and not Path(args.json).parent.is_dir():
        raise ParamError(f"--json = {args.json!r} is invalid: no folder {str(Path(args.json).parent)!r}")
    config = run_config(args, "moose reproduce")
    cache = RunCache(config, seed=args.seed, progress=lambda what: print(f"  {what}", file=sys.stderr, flush=True))
    runs = result_runs(cache, planners=args.planner or ())
    found = claims(cache)
    print(render_claims(found))
    wanted = {name for path in writes for name in blocks_in(path, GENERATED)}
    rendered = {"calibration": render_calibration(config.vehicle), "conditions": render_conditions(cache.asked),
                "results": render_results(runs),
                "claims": render_claims(found), "summary": render_summary(runs, found)}
    if args.variants or "variants" in wanted:
        rendered["variants"] = render_variants(variant_rows(cache))
        if args.variants:
            print()
            print(rendered["variants"])
    if args.json:
        rows = [{"scenario": r.scenario, "planner": r.planner, "solver": r.solver, "road_mu": r.mu,
                 "settings": dict(r.settings), **r.summary} for r in cache.asked]
        Path(args.json).write_text(json.dumps(rows, indent=2, allow_nan=False) + "\n", encoding="utf-8")
    for path in writes:
        names = blocks_in(path, GENERATED)
        update_document(path, {name: rendered[name] for name in names})
        print(f"wrote {', '.join(names)} of {path}")
    print(f"{len(cache)} runs", file=sys.stderr)
    return 0
