"""``moose reproduce``: re-run the paper's cases with every planner and judge its claims (:mod:`moose.reproduce`).

Prints the claims table; ``--write`` regenerates the generated blocks of docs/design.md (the
calibration, the results and the claims), ``--json`` writes every run's summary.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from ..params import ParamError
from .common import non_negative_int


def add_subparser(subparsers: Any) -> None:
    parser = subparsers.add_parser("reproduce", help="re-run the paper's cases and judge its claims")
    parser.add_argument("--config", help="ROS 2 parameter file (default config/moose.yaml)")
    parser.add_argument("--seed", type=non_negative_int, default=0, help="seed of the sensor noise (an integer >= 0)")
    parser.add_argument("--write", metavar="DESIGN_MD",
                        help="regenerate the calibration, results and claims blocks of this file (docs/design.md)")
    parser.add_argument("--json", help="write every run's summary as JSON to this path")
    parser.set_defaults(func=cmd_reproduce)


def cmd_reproduce(args: argparse.Namespace) -> int:
    from ..config import load_config
    from ..reproduce import claims, render_calibration, render_claims, render_results, run_all, update_document

    for option in ("write", "json"):
        path = getattr(args, option)
        if path is not None and not Path(path).parent.is_dir():
            raise ParamError(f"--{option} = {path!r} is invalid: no folder {str(Path(path).parent)!r}")
    if args.write is not None and not Path(args.write).is_file():
        raise ParamError(f"--write = {args.write!r} is invalid: no such file")
    config = load_config(args.config)
    runs = run_all(config, seed=args.seed, progress=lambda what: print(f"  {what}", file=sys.stderr, flush=True))
    found = claims(runs, config.mpc.solver, config.vehicle.delta_max)
    print(render_claims(found))
    if args.json:
        rows = [{"scenario": r.scenario, "planner": r.planner, "solver": r.solver, **r.summary} for r in runs]
        Path(args.json).write_text(json.dumps(rows, indent=2, allow_nan=False) + "\n", encoding="utf-8")
    if args.write:
        update_document(Path(args.write), {"calibration": render_calibration(config.vehicle),
                                           "results": render_results(runs), "claims": render_claims(found)})
        print(f"wrote the generated blocks of {args.write}")
    return 0
