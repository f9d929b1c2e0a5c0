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

from ..exiting import end_process
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
    """Run the command of ``argv`` (default: the command line); its exit status.  Run as the program (``argv``
    None), an interrupted command ends its process at once, without the interpreter's teardown
    (:func:`moose.exiting.end_process`)."""
    status = _command(argv)
    if status == EXIT_INTERRUPTED and argv is None:
        end_process(status)  # the command's cleanup has run; a C extension interrupted mid-call may abort teardown
    return status


def _command(argv: Sequence[str] | None) -> int:
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
    except BrokenPipeError:  # the reader of our output went away (`moose bag info … | head`): not an error of ours
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 128 + signal.SIGPIPE
    except Exception as exc:  # a Ctrl-C that surfaced as another error, the KeyboardInterrupt as its cause: inside
        if _interrupted(exc):  # a C extension (CasADi) a SystemError, "returned a result with an exception set";
            return EXIT_INTERRUPTED  # in a class body being made (importing matplotlib), a RuntimeError
        raise
    finally:
        INTERRUPTS.uninstall()
