"""Ending a process without the interpreter's teardown."""
from __future__ import annotations

import atexit
import os
import sys
from typing import NoReturn


def end_process(status: int) -> NoReturn:
    """End this process with exit status ``status`` once its own cleanup has run: the exit handlers run here
    (``atexit``: multiprocessing's, coverage.py's, logging's), the standard streams are flushed, and what is skipped
    is the interpreter's teardown (``os._exit``), where C extensions free what they still hold.

    Two such teardowns went wrong here: a C extension that a Ctrl-C interrupted mid-call aborted the process ("Fatal
    Python error: PyThreadState_Get: … the GIL is released", exit status -6 where 130 was due: 1 Ctrl-C of 60 in
    ``moose simulate`` under coverage, 2026-12-03), and Cyclone DDS's deletion of a node's domain, after the node
    had deleted its participant, hung until the node's teardown watchdog ended the process 10 s later (1 of 30
    fault-matrix launches alone, 4 of 36 in a CI run: docs/testing.md)."""
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe or stream: nothing more can be said
            pass
    os._exit(status)
