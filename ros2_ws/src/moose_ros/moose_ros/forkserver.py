"""Node processes forked from a preloaded server: what every node of a run would import and build, done once.

Every node on our Cyclone runtime spends most of its start-up on the same work: importing NumPy, CasADi,
cyclonedds and the core, and building the same message classes (rosbags' Jazzy store, each class's XTypes type
information, :mod:`moose_ros.cdr`'s compiled code) — about 0.7 of the 1 CPU-second a node takes to start, seven
times per run (docs/testing.md).  ``moose launch`` instead forks them from a :class:`ForkServer`
(``python -m moose_ros.forkserver NODE…``, by :func:`moose_ros.process.spawn`: it dies with the launcher), one per
launching process, kept from run to run (:func:`shared`).  The server does that work before any DDS entity or thread
exists, then forks one child per node on request.

A child *is* the node's process, as ``python -m moose_ros.nodes NAME ARGS`` would be (``runpy``, the same
``sys.argv``): its own process id, its output (stdout and stderr) on the pipe the launcher passed with the request,
the environment the server was started with (a node whose environment differs is started by ``exec`` instead:
:meth:`ForkServer.serves`), the parent-death signal set (the server's own dies with the launcher), signals at their
defaults; it creates its DDS participant itself.  :class:`ForkedProcess` is the launcher's handle of one child: the
part of :class:`subprocess.Popen` the launcher and the fault injector use (``pid``, ``poll``, ``wait``,
``send_signal``, ``kill``, ``stdout``).

Protocol (a ``SOCK_SEQPACKET`` socket pair, one JSON object per packet): the launcher sends ``{"module", "argv"}``
with the pipe's write end attached (``SCM_RIGHTS``); the server answers ``{"started": pid}`` or ``{"error": text}``,
and later ``{"exited": pid, "status": code}`` (negative: the signal that ended it).  A child that has ended stays a
zombie until the launcher answers ``{"reap": pid}``, so its process id cannot be reused while the launcher may
still signal it.  The server ends when the launcher closes its end.
"""
from __future__ import annotations

import gc
import json
import os
import queue
import select
import signal
import socket
import subprocess
import sys
import threading
from typing import IO, Any, Mapping, Optional, Sequence

from .process import PR_SET_PDEATHSIG, spawn, stat_fields

PACKET = 1 << 16
"""Largest packet (bytes): a node's arguments are a few kilobytes."""
START_TIMEOUT = 60.0
"""Seconds the launcher waits for the server's answer to a start request (the first one waits for the preload)."""


def preload(nodes: Sequence[str]) -> None:
    """Import the classes of ``nodes`` and the DDS runtime, and build every message class of the graph (the topics'
    types, the lockstep markers, ``ros_discovery_info``) with its type information and compiled CDR.  A node whose
    module fails to import is left to fail in its own child, where it is reported as a node that failed to start."""
    from .graph import TOPICS
    from .interfaces import message_class
    from .lockstep import TICK_TYPE
    from .nodes import node_class
    from .runtime.dds import DISCOVERY_TYPE

    for name in nodes:
        try:
            node_class(name)
        except Exception:  # noqa: BLE001 - reported by the node's own process
            pass
    for type_name in sorted({topic.type for topic in TOPICS.values()} | {TICK_TYPE, DISCOVERY_TYPE}):
        idl = message_class(type_name).__idl__
        idl.populate()
        idl.fill_type_data()  # what cyclonedds' Topic computes for each type (cached on the class)


def serve(channel: socket.socket) -> None:
    """The server's loop: fork a child per request, report each child's end, until the launcher closes
    ``channel``.  In a child, this call does not return: it raises the child's ``SystemExit``."""
    wake_r, wake_w = os.pipe()
    os.set_blocking(wake_w, False)
    signal.set_wakeup_fd(wake_w)
    signal.signal(signal.SIGCHLD, lambda *_: None)  # only to wake the select below
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the launcher; it ends the run
    running: set[int] = set()
    watched: list[Any] = [channel, wake_r]
    while True:
        ready, _, _ = select.select(watched, [], [])
        if wake_r in ready:
            os.read(wake_r, 4096)
        for pid in sorted(running):  # ended children: reported, kept as zombies until the launcher says reap
            info = os.waitid(os.P_PID, pid, os.WEXITED | os.WNOHANG | os.WNOWAIT)
            if info is not None:
                running.discard(pid)
                status = info.si_status if info.si_code == os.CLD_EXITED else -info.si_status
                _send(channel, {"exited": pid, "status": status})
        if channel not in ready:
            continue
        data, fds, _flags, _addr = socket.recv_fds(channel, PACKET, 1)
        if not data:  # the launcher is done (or gone): end, reaping what is left
            for pid in running:
                os.kill(pid, signal.SIGKILL)
            return
        request = json.loads(data)
        if "reap" in request:
            os.waitpid(request["reap"], 0)
            continue
        if len(fds) != 1:
            _send(channel, {"error": f"a start request carries one file descriptor, not {len(fds)}"})
            for fd in fds:
                os.close(fd)
            continue
        pid = os.fork()
        if pid == 0:
            os.close(wake_r)
            os.close(wake_w)
            _become(channel, fds[0], request["module"], request["argv"])  # raises SystemExit
        os.close(fds[0])
        running.add(pid)
        _send(channel, {"started": pid})


def _become(channel: socket.socket, output: int, module: str, argv: list[str]) -> None:
    """In a new child: become ``python -m MODULE ARGV…`` with its output on ``output``."""
    import ctypes
    import runpy

    server = os.getppid()
    channel.close()
    signal.set_wakeup_fd(-1)
    signal.signal(signal.SIGCHLD, signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0) != 0 or os.getppid() != server:
        os._exit(70)
    sys.stdout.flush()
    sys.stderr.flush()
    os.dup2(output, 1)
    os.dup2(output, 2)
    os.close(output)
    _retitle([sys.executable, "-m", module, *argv[:1]])
    sys.argv = [module, *argv]  # runpy replaces argv[0] with the module's file, as `python -m` does
    runpy.run_module(module, run_name="__main__", alter_sys=True)
    sys.exit(0)


def _retitle(words: list[str]) -> None:
    """Show this process as ``words`` (``ps``, ``pgrep -f``, ``/proc/PID/cmdline``: the command it runs, not the
    server's): written over the command line the server was started with, which is as long or longer (its
    arguments name every node), cut to fit and padded with NULs."""
    import ctypes

    fields = stat_fields("self")
    assert fields is not None
    start, end = int(fields[45]), int(fields[46])  # arg_start and arg_end, fields 48 and 49 of proc(5)
    title = "\0".join(words).encode()[:end - start - 1]
    ctypes.memmove(start, title + b"\0" * (end - start - len(title)), end - start)


def _send(channel: socket.socket, message: dict[str, Any]) -> None:
    channel.send(json.dumps(message).encode())


class ForkedProcess:
    """The launcher's handle of a child of a :class:`ForkServer`: what ``moose launch`` uses of
    :class:`subprocess.Popen` (its exit status comes from the server)."""

    def __init__(self, pid: int, args: list[str], stdout: IO[str]) -> None:
        self.pid, self.args, self.stdout = pid, args, stdout
        self.returncode: Optional[int] = None
        self._ended = threading.Event()

    def end(self, status: int) -> None:
        """The server reported the child's end (:class:`ForkServer`'s reader)."""
        self.returncode = status
        self._ended.set()

    def poll(self) -> Optional[int]:
        return self.returncode

    def wait(self, timeout: Optional[float] = None) -> int:
        if not self._ended.wait(timeout):
            raise subprocess.TimeoutExpired(self.args, timeout or 0.0)
        assert self.returncode is not None
        return self.returncode

    def send_signal(self, sig: int) -> None:
        """``sig`` to the child unless it has ended (it is then a zombie until reaped: its id is not reused)."""
        if self.returncode is None:
            try:
                os.kill(self.pid, sig)
            except ProcessLookupError:
                pass

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)

    def terminate(self) -> None:
        self.send_signal(signal.SIGTERM)


class ForkServer:
    """One preloading server (``python -m moose_ros.forkserver NODE…``, started now with ``env``) and the children
    it forks.  :meth:`start` starts ``python -m MODULE ARGV…`` as its child; :meth:`close` ends the server."""

    def __init__(self, nodes: Sequence[str], env: Mapping[str, str]) -> None:
        self.env = dict(env)
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        with theirs:
            self.proc = spawn([sys.executable, "-m", __name__, str(theirs.fileno()), *nodes], env=env,
                              pass_fds=(theirs.fileno(),))
        self.channel = ours
        self.children: dict[int, ForkedProcess] = {}
        self.answers: queue.Queue[dict[str, Any]] = queue.Queue()
        self.lock = threading.Lock()
        self.reader = threading.Thread(target=self._read, name="moose-forkserver", daemon=True)
        self.reader.start()

    def serves(self, python: str, env: Mapping[str, str]) -> bool:
        """Whether a process of interpreter ``python`` with environment ``env`` can be forked here (the same
        interpreter and environment as the server's; else it must be started by ``exec``)."""
        return python == sys.executable and dict(env) == self.env

    def start(self, module: str, argv: Sequence[str]) -> ForkedProcess:
        """``python -m MODULE ARGV…`` as a child of the server, its output (stdout and stderr) readable as text from
        the handle's ``stdout``.  An error starting it is an OSError."""
        read, write = os.pipe()
        try:
            with self.lock:
                try:
                    socket.send_fds(self.channel, [json.dumps({"module": module, "argv": list(argv)}).encode()],
                                    [write])
                    answer = self.answers.get(timeout=START_TIMEOUT)
                except OSError as exc:
                    answer = {"error": f"it is gone ({exc})"}
                except queue.Empty:
                    answer = {"error": f"no answer within {START_TIMEOUT:g} s"}
        finally:
            os.close(write)
        if "started" not in answer:
            os.close(read)
            raise OSError(f"the fork server could not start {module}: {answer['error']}")
        output = open(read, encoding=None)  # noqa: SIM115 - the child's output, read to its end as Popen's stdout
        child = ForkedProcess(answer["started"], [module, *argv], output)
        self.children[child.pid] = child
        return child

    def _read(self) -> None:
        """The server's answers and exit reports; when the server is gone its children are too (their parent-death
        signal): each still running ends with SIGKILL's status."""
        while True:
            try:
                data = self.channel.recv(PACKET)
            except OSError:
                data = b""
            if not data:
                break
            message = json.loads(data)
            if "exited" in message:
                child = self.children.pop(message["exited"], None)
                if child is not None:
                    child.end(message["status"])
                try:
                    _send(self.channel, {"reap": message["exited"]})
                except OSError:
                    break
            else:
                self.answers.put(message)
        self.answers.put({"error": "the fork server has ended"})
        for child in list(self.children.values()):
            if child.returncode is None:
                child.end(-signal.SIGKILL)

    def close(self, timeout: float = 5.0) -> None:
        """End the server (every child should have ended: any left is killed)."""
        try:
            self.channel.shutdown(socket.SHUT_WR)
        except OSError:
            pass
        try:
            self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        self.reader.join(timeout=timeout)
        self.channel.close()


_shared: list[ForkServer] = []


def shared(env: Mapping[str, str]) -> ForkServer:
    """This process's fork server for processes of environment ``env``, preloading every node of the graph: kept from
    run to run (a test process launches dozens of graphs), started anew when ``env`` differs from its own or it has
    ended (it dies with the thread that started it)."""
    from .graph import NODES

    if _shared and (not _shared[0].serves(sys.executable, env) or _shared[0].proc.poll() is not None):
        _shared.pop().close()
    if not _shared:
        _shared.append(ForkServer(sorted(NODES), env))
    return _shared[0]


def main(argv: Sequence[str]) -> None:
    """``python -m moose_ros.forkserver FD NODE…``: preload for ``NODE…``, then serve on the socket ``FD``."""
    channel = socket.socket(fileno=int(argv[0]))
    preload(argv[1:])
    gc.freeze()  # the preloaded heap is every child's: no collection in a child touches (and so copies) its pages
    serve(channel)


if __name__ == "__main__":
    main(sys.argv[1:])
