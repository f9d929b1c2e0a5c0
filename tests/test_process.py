"""moose_ros.process: children that die with their parent, a parent watch, stopping a stopped child."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from moose_ros.process import PARENT_ENV, descendants, spawn, state, stop

WATCHER = """
import sys, time
from moose_ros.process import watch_parent
watch_parent(lambda: print("parent gone", flush=True))
print("watching", flush=True)
time.sleep(30)
"""



def test_a_spawned_child_dies_with_its_sigkilled_parent() -> None:
    parent = subprocess.Popen([sys.executable, "-c", "from moose_ros.process import spawn; import time\n"
                               "p = spawn(['sleep', '60']); print(p.pid, flush=True); time.sleep(60)"],
                              stdout=subprocess.PIPE, text=True)
    try:
        assert parent.stdout is not None
        child = int(parent.stdout.readline())
        time.sleep(0.3)  # the shim has exec'd sleep
        assert descendants(parent.pid) == [child]
        assert Path(f"/proc/{child}/cmdline").read_text().startswith("sleep")
        assert f"{PARENT_ENV}={parent.pid}" in Path(f"/proc/{child}/environ").read_text().split("\0")
    finally:
        parent.kill()
        parent.wait()
    deadline = time.monotonic() + 5.0
    while state(child) not in ("gone", "Z") and time.monotonic() < deadline:
        time.sleep(0.05)
    assert state(child) in ("gone", "Z")  # killed by the parent-death signal (a zombie until init reaps it)


@pytest.mark.realtime  # how soon, against the wall clock: the serial phase
def test_a_child_notices_its_parent_is_gone_without_the_signal() -> None:
    """The second line of defence: a child that is not the spawner's own (no parent-death signal) but names it in
    MOOSE_PARENT_PID hears of its end through the pidfd."""
    stand_in = subprocess.Popen(["sleep", "30"])
    child = subprocess.Popen([sys.executable, "-c", WATCHER], stdout=subprocess.PIPE, text=True,
                             env={**os.environ, PARENT_ENV: str(stand_in.pid)})
    try:
        assert child.stdout is not None
        assert child.stdout.readline().strip() == "watching"
        started = time.monotonic()
        stand_in.kill()
        stand_in.wait()
        assert child.stdout.readline().strip() == "parent gone" and time.monotonic() - started < 2.0
    finally:
        stop([child, stand_in], grace=1.0)


@pytest.mark.realtime  # how soon, against the wall clock: the serial phase
def test_stop_ends_a_stopped_child_with_sigterm() -> None:
    child = spawn([sys.executable, "-c", "import signal, sys, time\n"
                   "signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))\nprint('up', flush=True)\ntime.sleep(30)"],
                  stdout=subprocess.PIPE, text=True)
    assert child.stdout is not None and child.stdout.readline().strip() == "up"
    child.send_signal(signal.SIGSTOP)
    started = time.monotonic()
    assert stop([child], grace=5.0) == {child.pid: 0}  # SIGCONT first: a stopped child acts on SIGTERM
    assert time.monotonic() - started < 3.0


EXIT_LATER = """\
import ctypes, sys
from moose_ros.process import exit_later
print(exit_later(0.2, int(sys.argv[1])), flush=True)
ctypes.PyDLL(None).sleep(120)  # holds the interpreter's lock: no Python thread runs again
print("not reached", flush=True)
"""


@pytest.mark.parametrize("status", [0, 3])
def test_exit_later_ends_a_process_whose_interpreter_lock_is_held(status: int) -> None:
    """A C call that never returns and holds the interpreter's lock (as rclpy's destroy_node does) blocks every
    Python thread; exit_later's POSIX timer still ends the process, with the status asked for."""
    child = spawn([sys.executable, "-c", EXIT_LATER, str(status)], stdout=subprocess.PIPE, text=True)
    try:
        out, _ = child.communicate(timeout=60)
    finally:
        stop([child], grace=1.0)
    assert (child.returncode, out) == (status, "posix\n")
