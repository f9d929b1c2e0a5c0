"""Resources a test run claims for itself: a DDS domain id and UDP ports that no other run on this machine uses.

A DDS domain is claimed with an exclusive, non-blocking ``flock`` on a file under the system's
temporary folder, held until :func:`release_domain` (or until the process dies: the kernel releases it,
even on SIGKILL), and only if the domain's RTPS well-known discovery ports can be bound on loopback
(:func:`domain_unused`), so a graph left over from another test or run is noticed.
Each test has a domain of its own (tests/conftest.py): the processes of every run on the machine claim the
domains in turn (a counter in a lock file, :data:`NEXT_DOMAIN`), so a domain released is the last any of them
takes again, and a participant an earlier test left behind (still ending, or leaked) has a whole round of
claims to go before a later test could meet it.
UDP ports for the CAN bus are taken from the kernel (bind to port 0) and held by a lock file too,
so two concurrent runs never share a bus.

Tests whose verdict depends on the wall clock (a graph paced in real time, the CAN bridge's schedule under a
flood) hold the machine's **real-time slot** (:func:`realtime_slot`, marker ``realtime``): one such test at a
time on the machine, the others of concurrent runs wait for it.  The graph needs cores of its own to keep
its timing (docs/ros2.md, "The graph on rclpy"); two runs that each start eight node processes at once
take them from each other.
"""
from __future__ import annotations

import contextlib
import fcntl
import os
import socket
import tempfile
import time
from pathlib import Path
from typing import IO, Iterator

LOCK_DIR = Path(tempfile.gettempdir()) / "moose-test-locks"
DOMAIN_IDS = range(1, 200)
"""Cyclone DDS accepts 0..232; 0 is ROS 2's default and is left to users."""

_held: dict[str, IO[str]] = {}
"""Lock file name → its open, locked handle."""


def _lock(name: str) -> bool:
    if name in _held:
        return False  # flock is per open file: this process would lock it a second time
    LOCK_DIR.mkdir(parents=True, exist_ok=True)
    handle = open(LOCK_DIR / name, "w", encoding="utf-8")  # noqa: SIM115 - held (with its lock) until released
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        handle.close()
        return False
    handle.write(str(os.getpid()))
    handle.flush()
    _held[name] = handle
    return True


def _udp_port_free(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 0)
        try:
            sock.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def domain_unused(domain: int) -> bool:
    """Whether no participant on this host holds the domain's discovery ports (RTPS's well-known ports): the
    multicast one, 7400 + 250 · id, bound by Cyclone DDS with SPDP multicast (the tests' configuration) and by
    Fast DDS, and the unicast one of participant index 0, 7410 + 250 · id, bound by Fast DDS (rclpy) and by Cyclone
    DDS with participant indices (the ``LOCALHOST`` configuration of tests/ros2_prefix.py)."""
    return _udp_port_free(7400 + 250 * domain) and _udp_port_free(7410 + 250 * domain)


NEXT_DOMAIN = "dds-domain-next"
"""Lock file holding the index in :data:`DOMAIN_IDS` where the machine's next claim starts looking (after the last
claim of any process)."""


def claim_domain() -> int:
    """A DDS domain id locked for this process and with its discovery port free; raises if none is left.

    The search starts after the last claim of any process on the machine (read and advanced under an exclusive lock
    of :data:`NEXT_DOMAIN`): the domains are taken in turn, and one just released is taken again only after every
    other."""
    LOCK_DIR.mkdir(parents=True, exist_ok=True)
    with open(LOCK_DIR / NEXT_DOMAIN, "a+", encoding="utf-8") as counter:
        fcntl.flock(counter, fcntl.LOCK_EX)  # released when the file closes
        counter.seek(0)
        text = counter.read().strip()
        start = int(text) % len(DOMAIN_IDS) if text.isdigit() else os.getpid() % len(DOMAIN_IDS)
        for i in range(len(DOMAIN_IDS)):
            index = (start + i) % len(DOMAIN_IDS)
            domain = DOMAIN_IDS[index]
            if domain_unused(domain) and _lock(f"dds-domain-{domain}"):
                counter.seek(0)
                counter.truncate()
                counter.write(str((index + 1) % len(DOMAIN_IDS)))
                return domain
    raise RuntimeError(f"no free DDS domain in {DOMAIN_IDS}: every one is locked by another test run")


def release_domain(domain: int) -> None:
    """Let go of a domain :func:`claim_domain` gave this process."""
    handle = _held.pop(f"dds-domain-{domain}")
    fcntl.flock(handle, fcntl.LOCK_UN)
    handle.close()


def claim_udp_port() -> int:
    """A UDP port that is free now (the kernel's choice) and locked for this process."""
    for _ in range(100):
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            sock.bind(("127.0.0.1", 0))
            port = int(sock.getsockname()[1])
        if _lock(f"udp-port-{port}"):
            return port
    raise RuntimeError("no free UDP port found")


REALTIME_WAIT = 3600.0
"""Seconds a test waits for the real-time slot before it fails (another run's graph tests hold it meanwhile)."""

_depth: dict[str, int] = {}
"""Nesting depth of :func:`realtime_slot` per slot in this process (a module fixture and its tests both ask)."""


@contextlib.contextmanager
def realtime_slot(wait: float = REALTIME_WAIT, name: str = "realtime") -> Iterator[None]:
    """Hold the machine's real-time slot ``name`` (an exclusive ``flock``; re-entrant within this process)."""
    if _depth.get(name):
        _depth[name] += 1
        try:
            yield
        finally:
            _depth[name] -= 1
        return
    LOCK_DIR.mkdir(parents=True, exist_ok=True)
    path = LOCK_DIR / name
    with open(path, "w", encoding="utf-8") as handle:
        deadline = time.monotonic() + wait
        while True:
            try:
                fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if time.monotonic() > deadline:
                    raise RuntimeError(f"the real-time slot {path} stayed held by another run for {wait} s") from None
                time.sleep(0.02)  # often: the holder of another run takes it again between two of its tests
        _depth[name] = 1
        try:
            yield
        finally:
            _depth[name] = 0
            fcntl.flock(handle, fcntl.LOCK_UN)
