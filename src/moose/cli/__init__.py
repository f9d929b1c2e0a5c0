"""The ``moose`` command: built-in commands, and commands of installed plugins.

Built in: ``simulate`` (one moose test in lockstep, :mod:`.simulate`), ``can`` (vehicle-bus
tools, :mod:`.can`) and ``sweep`` (many moose tests and their maps, :mod:`.sweep`).  Other packages add commands through entry points (:mod:`.plugins`); the
node graph's ``node``, ``launch`` and ``bag`` come with moose_ros.  Bad input ends with
``moose: error: …`` naming the field and the value, and a non-zero exit status.
"""
from __future__ import annotations

import argparse
import sys
from typing import Callable, Sequence

from ..params import ParamError
from . import can, simulate, sweep
from .common import DEFAULT_SCENARIO
from .plugins import add_plugin_commands

__all__ = ["DEFAULT_SCENARIO", "build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="moose", description="Emergency collision avoidance for a sudden static obstacle (the moose test).",
        epilog="The node graph's commands (node, launch, bag) come with the moose_ros package.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    simulate.add_subparser(sub)
    can.add_subparser(sub)
    sweep.add_subparser(sub)
    add_plugin_commands(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    handler: Callable[[argparse.Namespace], int] = args.func
    try:
        return handler(args)
    except ParamError as exc:
        print(f"moose: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
