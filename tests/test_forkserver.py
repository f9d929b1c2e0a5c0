"""moose_ros.forkserver: a forked child is the process ``python -m MODULE ARGS`` would be — its arguments, its output,
its exit status or the signal that ended it, stopped and continued, gone with its launcher — and the server hands
out a child's end exactly once, with no process id reused under the launcher's signals."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Iterator

import pytest

from moose_ros.forkserver import ForkServer
from moose_ros.process import PARENT_ENV, descendants, state

CHILD = """
import os, sys, time
print("argv", sys.argv[1:], "name", __name__, "parent", os.environ.get("MOOSE_PARENT_PID"), flush=True)
print("to stderr", file=sys.stderr, flush=True)
action = sys.argv[1]
if action == "exit":
    sys.exit(int(sys.argv[2]))
if action == "raise":
    raise RuntimeError("boom")
if action == "sleep":
    time.sleep(float(sys.argv[2]))
"""



@pytest.fixture
def server(tmp_path: Path) -> Iterator[ForkServer]:
    (tmp_path / "forkchild.py").write_text(CHILD)
    forks = ForkServer([], {**os.environ, "PYTHONPATH": str(tmp_path)})
    try:
        yield forks
    finally:
        for child in forks.children.values():
            child.kill()
        forks.close()


def test_a_child_is_python_dash_m_with_its_arguments_output_and_exit_status(server: ForkServer) -> None:
    child = server.start("forkchild", ["exit", "3"])
    assert child.wait(timeout=60) == 3
    lines = child.stdout.read().splitlines()
    assert lines == [f"argv ['exit', '3'] name __main__ parent {os.getpid()}", "to stderr"]
    assert server.proc.pid != child.pid and child.poll() == 3


def test_an_uncaught_exception_is_status_1_with_its_traceback(server: ForkServer) -> None:
    child = server.start("forkchild", ["raise"])
    assert child.wait(timeout=60) == 1
    output = child.stdout.read()
    assert "Traceback" in output and "RuntimeError: boom" in output


def test_signals_reach_the_child_and_a_kill_is_its_status(server: ForkServer) -> None:
    child = server.start("forkchild", ["sleep", "60"])
    assert child.stdout.readline().startswith("argv")  # it runs
    assert child.pid in descendants(os.getpid())  # below this process: the server's child
    child.send_signal(signal.SIGSTOP)
    deadline = time.monotonic() + 10
    while state(child.pid) != "T" and time.monotonic() < deadline:
        time.sleep(0.01)
    assert state(child.pid) == "T"
    with pytest.raises(subprocess.TimeoutExpired):
        child.wait(timeout=0.2)
    child.send_signal(signal.SIGCONT)
    child.kill()
    assert child.wait(timeout=10) == -signal.SIGKILL
    child.kill()  # an ended child is not signalled again (its process id may belong to another process)


def test_a_child_that_ends_at_once_is_reported_and_then_reaped(server: ForkServer) -> None:
    children = [server.start("forkchild", ["exit", str(code)]) for code in range(8)]
    assert [c.wait(timeout=60) for c in children] == list(range(8))
    deadline = time.monotonic() + 10
    while any(state(c.pid) != "gone" for c in children) and time.monotonic() < deadline:
        time.sleep(0.01)
    assert [state(c.pid) for c in children] == ["gone"] * 8  # the launcher's reap reached the server


def test_only_the_servers_interpreter_and_environment_are_forked(server: ForkServer) -> None:
    assert server.serves(sys.executable, server.env)
    assert not server.serves("/usr/bin/python3.12", server.env)
    assert not server.serves(sys.executable, {**server.env, "MOOSE_RUNTIME": "rclpy"})


LAUNCHER = """
import os, sys, time
from moose_ros.forkserver import ForkServer
forks = ForkServer([], {**os.environ, "PYTHONPATH": sys.argv[1]})
child = forks.start("forkchild", ["sleep", "60"])
child.stdout.readline()
print(forks.proc.pid, child.pid, flush=True)
time.sleep(60)
"""


def test_the_server_and_its_children_die_with_a_sigkilled_launcher(tmp_path: Path) -> None:
    (tmp_path / "forkchild.py").write_text(CHILD)
    launcher = subprocess.Popen([sys.executable, "-c", LAUNCHER, str(tmp_path)], stdout=subprocess.PIPE, text=True)
    try:
        assert launcher.stdout is not None
        server, child = map(int, launcher.stdout.readline().split())
        assert {server, child} <= set(descendants(launcher.pid))
        assert f"{PARENT_ENV}={launcher.pid}" in Path(f"/proc/{child}/environ").read_text().split("\0")
    finally:
        launcher.kill()
        launcher.wait()
    deadline = time.monotonic() + 10.0
    while {state(server), state(child)} - {"gone", "Z"} and time.monotonic() < deadline:
        time.sleep(0.05)
    assert {state(server), state(child)} <= {"gone", "Z"}  # parent-death signals, launcher → server → child


def test_a_sigkilled_server_takes_its_children_and_their_handles_say_so(server: ForkServer) -> None:
    """The child's own parent-death signal: with the server gone, nothing of its children survives, and the
    launcher's handles report them killed."""
    child = server.start("forkchild", ["sleep", "60"])
    assert child.stdout.readline().startswith("argv")
    server.proc.kill()
    assert child.wait(timeout=10) == -signal.SIGKILL
    deadline = time.monotonic() + 10.0
    while state(child.pid) not in ("gone", "Z") and time.monotonic() < deadline:
        time.sleep(0.05)
    assert state(child.pid) in ("gone", "Z")
    with pytest.raises(OSError, match="fork server"):
        server.start("forkchild", ["exit", "0"])


def test_ps_shows_a_child_as_the_command_it_runs(server: ForkServer) -> None:
    """/proc/PID/cmdline (ps, pgrep -f) names the module and its first argument, not the server."""
    child = server.start("forkchild", ["sleep", "60"])
    assert child.stdout.readline().startswith("argv")
    argv = [a for a in Path(f"/proc/{child.pid}/cmdline").read_bytes().split(b"\0") if a]
    assert argv == [sys.executable.encode(), b"-m", b"forkchild", b"sleep"]
    child.kill()
    child.wait(timeout=10)


def test_a_process_keeps_one_server_per_environment_and_replaces_an_ended_one(tmp_path: Path) -> None:
    """moose_ros.forkserver.shared: the same server for the same environment from run to run; another for another
    environment (the first one ends); a new one when the old one has died."""
    from moose_ros import forkserver

    env = {**os.environ, "PYTHONPATH": str(tmp_path)}
    first = forkserver.shared(env)
    try:
        assert forkserver.shared(dict(env)) is first
        second = forkserver.shared({**env, "MOOSE_TEST_OTHER": "1"})
        assert second is not first and first.proc.wait(timeout=10) is not None
        second.proc.kill()
        second.proc.wait()
        third = forkserver.shared({**env, "MOOSE_TEST_OTHER": "1"})
        assert third is not second and third.proc.poll() is None
    finally:
        while forkserver._shared:
            forkserver._shared.pop().close()
