"""Child processes that die with their parent: how ``moose launch`` (and tests) start the node graph.

:func:`spawn` starts a command so that it cannot outlive the process that started it, even when that
process is SIGKILLed:

* **Parent-death signal, set race-free.**  The child first runs a few lines of Python (``python -S -c``,
  standard library only, no ``preexec_fn``: that is unsafe in a process with threads, and the launcher has
  DDS and output threads) which set ``prctl(PR_SET_PDEATHSIG, SIGKILL)`` and then check that their parent
  is still the spawning process — if it died between ``fork`` and ``prctl`` the child has been re-parented
  and exits at once — and then ``exec`` the command.  The setting survives ``exec`` (not into set-user-ID
  programs).  SIGKILL, not SIGTERM: it also ends a child that is stopped (SIGSTOP), and a CAN bridge that
  falls silent lets the vehicle's ECUs time out, which is its designed fail-safe.  Linux sends the signal
  when the *thread* that spawned the child ends: spawn from a thread that lives as long as the children
  (``moose launch`` spawns from its main thread).
* **The child watches its parent.**  :data:`PARENT_ENV` carries the spawning process's id; a node
  (:func:`moose_ros.nodes.run`) calls :func:`watch_parent`, which waits on a pidfd of that process
  (Linux ≥ 5.3; else it polls ``getppid``) and shuts the node down when it is gone — the second line of
  defence, for a child that is not a direct one (a wrapper script in between) or that runs on a system
  without the parent-death signal.

:func:`stop` ends a set of children as the launcher does at the end of a run: SIGCONT (a stopped child
cannot act on SIGTERM), SIGTERM, then SIGKILL after a grace period.  :func:`descendants` lists the living
processes below a process (``/proc``), for tests that check that nothing survived.  :func:`exit_later` ends the
process after a delay even while a C extension holds the interpreter's lock (a node's bound on a hung teardown).
"""
from __future__ import annotations

import ctypes
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import IO, Any, Callable, Iterable, Mapping, Optional, Protocol, Sequence, Union

PARENT_ENV = "MOOSE_PARENT_PID"
"""Environment variable with the id of the process that spawned a child (:func:`spawn`)."""

PR_SET_PDEATHSIG = 1
"""``prctl`` option (linux/prctl.h)."""

_SHIM = """\
import ctypes, os, signal, sys
parent = int(sys.argv[1])
libc = ctypes.CDLL(None, use_errno=True)
if libc.prctl(1, int(signal.SIGKILL), 0, 0, 0) != 0:
    sys.stderr.write(f"moose: error: prctl(PR_SET_PDEATHSIG) failed: {os.strerror(ctypes.get_errno())}\\n")
    os._exit(70)
if os.getppid() != parent:
    os._exit(70)
os.execvp(sys.argv[2], sys.argv[2:])
"""
"""Runs in the child before the command: the parent-death signal, the race check, ``exec``."""


class Child(Protocol):
    """What the launcher uses of a node's process: a :class:`subprocess.Popen` of :func:`spawn`, or a
    :class:`moose_ros.forkserver.ForkedProcess`."""

    @property
    def pid(self) -> int: ...

    @property
    def returncode(self) -> Optional[int]: ...

    @property
    def stdout(self) -> Optional[IO[str]]: ...

    def poll(self) -> Optional[int]: ...

    def wait(self, timeout: Optional[float] = None) -> int: ...

    def send_signal(self, sig: int) -> None: ...

    def kill(self) -> None: ...


def spawn(cmd: Sequence[str], env: Optional[Mapping[str, str]] = None, **popen: Any) -> subprocess.Popen:
    """Start ``cmd`` (``subprocess.Popen`` with ``popen``'s other arguments) so that it dies with this process:
    SIGKILL when this process (the spawning thread) ends, and :data:`PARENT_ENV` set for :func:`watch_parent`.
    Without ``prctl`` (not Linux) the command is started as is, with :data:`PARENT_ENV` set."""
    child_env = dict(os.environ if env is None else env)
    child_env[PARENT_ENV] = str(os.getpid())
    if sys.platform.startswith("linux"):
        cmd = [sys.executable, "-S", "-c", _SHIM, str(os.getpid()), *cmd]
    return subprocess.Popen(list(cmd), env=child_env, **popen)


def watch_parent(on_exit: Callable[[], None], poll: float = 0.2) -> Optional[threading.Thread]:
    """Call ``on_exit`` (once, from a daemon thread) when the process named by :data:`PARENT_ENV` is gone;
    at once if it is gone already.  ``None`` (nothing watched) when this process was not started by
    :func:`spawn`."""
    raw = os.environ.get(PARENT_ENV, "")
    if not raw.isdigit():
        return None
    parent = int(raw)
    pidfd: Optional[int] = None
    try:
        pidfd = os.pidfd_open(parent)
    except ProcessLookupError:
        on_exit()
        return None
    except (AttributeError, OSError):  # no pidfd (old kernel, not Linux): poll our parent id
        pidfd = None

    def wait() -> None:
        if pidfd is not None:
            import select

            select.select([pidfd], [], [])  # readable when the process has ended
            os.close(pidfd)
        else:
            while os.getppid() == parent:
                time.sleep(poll)
        on_exit()

    thread = threading.Thread(target=wait, name="moose-parent-watch", daemon=True)
    thread.start()
    return thread


class _SigVal(ctypes.Union):
    _fields_ = [("sival_int", ctypes.c_int), ("sival_ptr", ctypes.c_void_p)]


class _SigEvThread(ctypes.Structure):
    _fields_ = [("function", ctypes.c_void_p), ("attribute", ctypes.c_void_p)]


class _SigEvUnion(ctypes.Union):
    _fields_ = [("pad", ctypes.c_int * 12), ("tid", ctypes.c_int), ("thread", _SigEvThread)]


class _SigEvent(ctypes.Structure):
    """``struct sigevent`` of Linux (64 bytes on 64-bit systems)."""

    _fields_ = [("value", _SigVal), ("signo", ctypes.c_int), ("notify", ctypes.c_int), ("un", _SigEvUnion)]


class _TimeSpec(ctypes.Structure):
    _fields_ = [("tv_sec", ctypes.c_long), ("tv_nsec", ctypes.c_long)]


class _ITimerSpec(ctypes.Structure):
    _fields_ = [("it_interval", _TimeSpec), ("it_value", _TimeSpec)]


SIGEV_THREAD = 2
"""``sigev_notify``: call a function on a new thread at expiry (signal.h)."""
CLOCK_MONOTONIC = 1
"""``clockid_t`` of the monotonic clock (time.h)."""


def exit_later(seconds: float, status: int = 0) -> str:
    """End this process with ``_exit(status)`` in ``seconds``, whatever its threads are doing.

    A POSIX timer (``timer_create`` with ``SIGEV_THREAD``) whose expiry calls the C library's ``_exit`` with
    ``status`` on a thread of the C library's own: it needs neither the interpreter's lock nor its main thread,
    so a C extension that hangs while holding the lock (rclpy's ``destroy_node`` does not release it, and hung in
    Fast DDS's teardown) cannot hold it off, as it would a Python thread.  Where the C library has no such timer
    (not glibc), a Python timer thread does it.  Returns which of the two is armed: ``"posix"`` or ``"python"``."""
    whole, frac = divmod(max(seconds, 1e-3), 1.0)
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        create, settime, end = libc.timer_create, libc.timer_settime, libc._exit
    except (AttributeError, OSError):
        create = None
    if create is not None:
        event = _SigEvent()
        event.notify = SIGEV_THREAD
        event.value.sival_int = status
        event.un.thread.function = ctypes.cast(end, ctypes.c_void_p).value
        timer = ctypes.c_void_p()
        spec = _ITimerSpec()
        spec.it_value.tv_sec, spec.it_value.tv_nsec = int(whole), int(frac * 1e9)
        if create(CLOCK_MONOTONIC, ctypes.byref(event), ctypes.byref(timer)) == 0:
            if settime(timer, 0, ctypes.byref(spec), None) == 0:
                return "posix"
    fallback = threading.Timer(seconds, os._exit, (status,))
    fallback.daemon = True
    fallback.start()
    return "python"


def stop(procs: Iterable[Child], grace: float = 5.0) -> dict[int, int]:
    """End ``procs``: SIGCONT and SIGTERM to each one still running, SIGKILL to those alive after ``grace``
    seconds; returns pid → exit status (negative: the signal that ended it)."""
    procs = list(procs)
    for proc in procs:
        if proc.poll() is None:
            for sig in (signal.SIGCONT, signal.SIGTERM):
                try:
                    proc.send_signal(sig)
                except ProcessLookupError:
                    pass
    deadline = time.monotonic() + grace
    codes = {}
    for proc in procs:
        try:
            codes[proc.pid] = proc.wait(timeout=max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            proc.kill()
            codes[proc.pid] = proc.wait()
    return codes


def stat_fields(pid: Union[int, str]) -> Optional[list[str]]:
    """The fields of ``/proc/PID/stat`` after the command name (``pid`` may be ``"self"``): ``[0]`` is field 3 of
    proc(5), the state; None when the process is gone (Linux)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return stat[stat.rindex(")") + 2:].split()


def state(pid: int) -> str:
    """The state letter of process ``pid`` (``R``, ``S``, ``T``: stopped, ``Z``: a zombie, …), or ``"gone"``."""
    fields = stat_fields(pid)
    return "gone" if fields is None else fields[0]


def descendants(pid: int) -> list[int]:
    """The living (not zombie) processes below ``pid``, from ``/proc`` (Linux)."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        fields = stat_fields(entry.name) if entry.name.isdigit() else None
        if fields is not None and fields[0] != "Z":
            children.setdefault(int(fields[1]), []).append(int(entry.name))
    out: list[int] = []
    todo = [pid]
    while todo:
        for child in children.get(todo.pop(), []):
            out.append(child)
            todo.append(child)
    return out
