"""``moose benchmark``: every planner over the paper region at μ = 0.33 and 0.8, and the leaderboard
(:mod:`moose.benchmark`).

Runs the benchmark's sweep (``moose sweep`` with the axes of :data:`moose.benchmark.AXES`; ``--resume`` continues
it, or only redraws a complete one), then writes DIR/leaderboard.md and DIR/leaderboard.png; ``--figure PNG``
writes the figure there too and ``--write FILE`` regenerates the ``leaderboard`` block of FILE
(docs/benchmarks.md).  Exit status: the sweep's (0, 3 when a case did not finish, 130 interrupted: then no
leaderboard), 2 for bad input.
"""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from ..params import ParamError
from .common import positive_float

COMMAND = "moose benchmark -o runs/benchmark --write docs/benchmarks.md --figure docs/maps/leaderboard.png"
"""The command that generates docs/benchmarks.md's leaderboard and its figure."""


def add_subparser(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "benchmark", help="every planner over the paper region at mu 0.33 and 0.8, and the leaderboard",
        description="Run the open benchmark (a sweep of every planner over the paper region, v 4-8 m/s, tau 1-5 s, "
                    "nu 0.1-1.0, at mu 0.33 and 0.8: 4,500 cases) and write its leaderboard: safe envelope, clear "
                    "and collision-free shares, mean clearance, worst sideslip, steering effort.",
        epilog=f"the leaderboard of docs/benchmarks.md: {COMMAND}")
    parser.add_argument("-o", "--output", default="runs/benchmark", help="the sweep's folder (default runs/benchmark)")
    parser.add_argument("--resume", action="store_true",
                        help="continue the benchmark in -o (a complete one is only drawn again)")
    parser.add_argument("--workers", type=int, help="local worker processes (default: the number of cores)")
    parser.add_argument("--timeout", type=positive_float, default=300.0, help="time limit of one case, s (default 300)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument("--figure", metavar="PNG", help="also write the leaderboard's figure to this path")
    parser.add_argument("--write", metavar="MARKDOWN", action="append", default=[],
                        help="regenerate the 'leaderboard' block of this file (docs/benchmarks.md); may be given more "
                             "than once")
    parser.set_defaults(func=cmd_benchmark)


def cmd_benchmark(args: argparse.Namespace) -> int:
    from ..benchmark import AXES, leaderboard, plot_leaderboard, render_leaderboard
    from ..reproduce import blocks_in, update_document
    from ..sweep.store import RunFolder
    from .common import check_output_file
    from .sweep import add_subparser as add_sweep

    writes = [Path(p) for p in args.write]
    for path in writes:
        if not path.is_file():
            raise ParamError(f"--write = {str(path)!r} is invalid: no such file")
        if not blocks_in(path, ["leaderboard"]):
            raise ParamError(f"--write = {str(path)!r} is invalid: it holds no generated block 'leaderboard' "
                             "(<!-- BEGIN leaderboard --> ... <!-- END leaderboard -->)")
    figure = check_output_file("--figure", args.figure, ("png",))
    flags = [token for name, value in AXES.items() for token in (f"--{name}", value)]
    flags += ["-o", args.output, "--timeout", str(args.timeout)]
    flags += ["--resume"] if args.resume else []
    flags += ["--workers", str(args.workers)] if args.workers is not None else []
    flags += ["--quiet"] if args.quiet else []
    parser = argparse.ArgumentParser(prog="moose")
    add_sweep(parser.add_subparsers())
    sweep = parser.parse_args(["sweep", *flags])  # the command moose sweep, with its checks
    status = int(sweep.func(sweep))
    if status not in (0, 3):
        return status
    entries = leaderboard(RunFolder(Path(args.output)).rows())
    table = render_leaderboard(entries)
    folder = Path(args.output)
    (folder / "leaderboard.md").write_text(table + "\n", encoding="utf-8")
    print(table)
    print(f"leaderboard     {folder / 'leaderboard.md'}")
    print(f"figure          {plot_leaderboard(entries, folder / 'leaderboard.png')}")
    if figure is not None:
        print(f"figure          {plot_leaderboard(entries, figure)}")
    for path in writes:
        update_document(path, {"leaderboard": table})
        print(f"wrote leaderboard of {path}")
    return status
