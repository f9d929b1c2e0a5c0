"""The ``moose`` command: built-in commands, and commands of installed plugins.

Built in: ``simulate`` (one moose test in lockstep, :mod:`.simulate`), ``reproduce`` (the
paper's cases and claims, :mod:`.reproduce`), ``sweep`` (many moose tests and their maps,
:mod:`.sweep`), ``budget`` (the latency budget of the paper's cases, :mod:`.budget`), ``benchmark``
(every planner over the paper region, the leaderboard, :mod:`.benchmark`) and ``can`` (vehicle-bus tools,
:mod:`.can`).  Other packages add commands through entry points (:mod:`.plugins`); the node graph's
``node``, ``launch`` and ``bag`` come with moose_ros.  Bad input ends with ``moose: error: …`` naming the field and
the value, and exit status 2; an output that cannot be written once the work is done (a full disk) ends with
``moose: error: …`` after the result, and exit status 5; Ctrl-C with 130 (:mod:`moose.cli.common` lists every
exit status).
"""
from __future__ import annotations

import argparse
import os
import signal
import sys
from typing import Callable, Sequence

from ..files import OutputError
from ..params import ParamError
from ..scenario import DEFAULT_SCENARIO
from ..verdict import EXIT_BAD_INPUT, EXIT_INTERRUPTED, EXIT_OUTPUT
from . import benchmark, budget, can, reproduce, simulate, sweep
from .common import INTERRUPTS
from .plugins import add_plugin_commands

__all__ = ["DEFAULT_SCENARIO", "build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="moose", description="Emergency collision avoidance for a sudden static obstacle (the moose test).",
        epilog="The node graph's commands (node, launch, bag) come with the moose_ros package.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    simulate.add_subparser(sub)
    can.add_subparser(sub)
    reproduce.add_subparser(sub)
    sweep.add_subparser(sub)
    budget.add_subparser(sub)
    benchmark.add_subparser(sub)
    add_plugin_commands(sub)
    return parser


def _interrupted(exc: BaseException) -> bool:
    """Whether ``exc`` was caused by a KeyboardInterrupt (somewhere down its chain)."""
    seen: set[int] = set()
    cause: BaseException | None = exc
    while cause is not None and id(cause) not in seen:
        if isinstance(cause, KeyboardInterrupt):
            return True
        seen.add(id(cause))
        cause = cause.__cause__ or cause.__context__
    return False


def main(argv: Sequence[str] | None = None) -> int:
    INTERRUPTS.install()
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        handler: Callable[[argparse.Namespace], int] = args.func
        status = handler(args)
        INTERRUPTS.check()  # a Ctrl-C that a C extension swallowed still ends the command with 130
        sys.stdout.flush()  # here, so a closed pipe is handled below and not at exit
        return status
    except ParamError as exc:
        print(f"moose: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except OutputError as exc:  # after the result was reported
        print(f"moose: error: {exc}", file=sys.stderr)
        return EXIT_OUTPUT
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED
    except SystemError as exc:  # Ctrl-C inside a C extension (CasADi) surfaces as "returned a result with an
        if _interrupted(exc):   # exception set", the KeyboardInterrupt as its cause
            return EXIT_INTERRUPTED
        raise
    except BrokenPipeError:  # the reader of our output went away (`moose bag info … | head`): not an error of ours
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 128 + signal.SIGPIPE
    finally:
        INTERRUPTS.uninstall()
