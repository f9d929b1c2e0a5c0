"""Plugins of the ``moose`` command, registered by entry points (as python-can registers interfaces).

- ``moose.commands``: each entry point is a function ``add_subparser(subparsers)`` that adds one
  sub-command named like the entry point and sets its handler with ``set_defaults(func=handler)``;
  the handler takes the parsed arguments and returns the exit status.  moose_ros provides ``node``,
  ``launch`` and ``bag``.
- ``moose.recorders``: a function ``record(result, path)`` that writes a lockstep run
  (:class:`moose.simulation.SimulationResult`) into a new bag directory; ``moose simulate`` uses it
  (moose_ros provides ``bag``).

Handlers and recorders report bad input by raising :class:`moose.params.ParamError`, and an output that cannot
be written once the work is done (a recorder on a full disk) by raising :class:`moose.files.OutputError`.
"""
from __future__ import annotations

import sys
from importlib.metadata import EntryPoint, entry_points
from typing import Any, Callable, Optional

COMMANDS = "moose.commands"
RECORDERS = "moose.recorders"


def _group(name: str) -> list[EntryPoint]:
    return sorted(entry_points(group=name), key=lambda ep: ep.name)


def add_plugin_commands(subparsers: Any) -> None:
    """Add every installed plugin command; one that fails to load is reported on stderr and left out."""
    for ep in _group(COMMANDS):
        if ep.name in subparsers.choices:
            print(f"moose: warning: command {ep.name!r} of {ep.value} is ignored: {ep.name!r} exists already",
                  file=sys.stderr)
            continue
        try:
            ep.load()(subparsers)
        except Exception as exc:  # noqa: BLE001 - a broken plugin must not take the other commands with it
            print(f"moose: warning: command {ep.name!r} of {ep.value} cannot be loaded: {exc}", file=sys.stderr)


def recorder() -> Optional[Callable[[Any, Any], Any]]:
    """The installed bag recorder (the first of group ``moose.recorders`` by name), or ``None``."""
    for ep in _group(RECORDERS):
        return ep.load()
    return None
