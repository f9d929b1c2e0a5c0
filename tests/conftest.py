"""Test-run isolation: a DDS domain of our own on loopback only, a private compile cache, and no process that
outlives the run."""
from __future__ import annotations

import os
import subprocess
import sys
import uuid
from pathlib import Path
from typing import Any, Iterator

import pytest

from isolation import claim_domain, realtime_slot
from ros2_prefix import dds_env, ros_env  # noqa: F401 - fixtures of the ROS 2 prefix tests

SESSION_MARK = "MOOSE_TEST_SESSION"
"""Environment variable every process a test run starts inherits: the run's own mark."""

REAPER = r'''
import os, signal, sys, time
mark = sys.argv[1].encode()
sys.stdin.buffer.read()  # end of file: the test run ended, normally or killed (the kernel closes the pipe)
me = os.getpid()

def marked():
    pids = []
    for entry in os.listdir("/proc"):
        if entry.isdigit() and int(entry) != me:
            try:
                with open(f"/proc/{entry}/environ", "rb") as f:
                    if mark in f.read().split(b"\0"):
                        pids.append(int(entry))
            except OSError:
                pass
    return pids

for sig, grace in ((signal.SIGTERM, 3.0), (signal.SIGKILL, 1.0)):
    pids = marked()
    for pid in pids:
        try:
            os.kill(pid, sig)
        except OSError:
            pass
    deadline = time.monotonic() + grace
    while pids and time.monotonic() < deadline:
        time.sleep(0.05)
        pids = marked()
'''


@pytest.fixture(scope="session", autouse=True)
def reaper() -> Iterator[None]:
    """Every process started by this test run (and its children, whatever process group they chose) carries
    :data:`SESSION_MARK` in its environment; a reaper outside the run's process group waits for the run to end —
    also a SIGKILLed one — and then ends every process with the mark still running (SIGTERM, then SIGKILL)."""
    mark = f"{SESSION_MARK}={uuid.uuid4().hex}"
    key, value = mark.split("=", 1)
    os.environ[key] = value
    proc = subprocess.Popen([sys.executable, "-c", REAPER, mark], stdin=subprocess.PIPE, start_new_session=True)
    yield
    assert proc.stdin is not None
    proc.stdin.close()  # the run is over: end what it left behind
    proc.wait(timeout=30)


@pytest.fixture(autouse=True)
def realtime(request: pytest.FixtureRequest) -> Iterator[None]:
    """A test marked ``realtime`` holds the machine's real-time slot (tests/isolation.py) while it runs."""
    if request.node.get_closest_marker("realtime") is None:
        yield
        return
    with realtime_slot():
        yield


@pytest.fixture(scope="session", autouse=True)
def dds_loopback(tmp_path_factory: pytest.TempPathFactory) -> None:
    """A ROS_DOMAIN_ID claimed for this test run (tests/isolation.py); Cyclone DDS bound to the loopback interface."""
    config = tmp_path_factory.mktemp("dds") / "cyclonedds.xml"
    config.write_text(
        '<CycloneDDS><Domain Id="any"><General><Interfaces><NetworkInterface name="lo"/></Interfaces>'
        "<AllowMulticast>spdp</AllowMulticast></General></Domain></CycloneDDS>"
    )
    os.environ["ROS_DOMAIN_ID"] = str(claim_domain())
    os.environ["CYCLONEDDS_URI"] = config.as_uri()
    os.environ["MOOSE_RUNTIME"] = "dds"
    os.environ.setdefault("MOOSE_CACHE_DIR", str(Path.home() / ".cache" / "moose"))


@pytest.fixture(scope="session")
def paper_runs() -> Any:
    """The runs of the paper's cases with the default configuration and seed 0, each made once for the whole test
    session (:class:`moose.reproduce.RunCache`): the claims, the tables and the closed-loop tests share them."""
    from moose.config import load_config
    from moose.reproduce import RunCache

    return RunCache(load_config())
