"""Test runs do not share resources and leave nothing running: checked from outside, with real processes.

* Two test runs at once claim different DDS domains and UDP ports (tests/isolation.py), also when a domain's
  discovery port is taken by a process that holds no lock (a graph left running by something else).
* Each test has a domain of its own, locked while it runs; the machine's processes claim the domains in turn.
* Two test runs at once, of tests that start graphs on DDS, use CAN buses on UDP and hold the real-time slot,
  both pass (the whole suite twice at once is run by hand: 2 × 30 min does not fit CI's budget).
* The real-time slot is held by one process at a time: another waits for it, and fails after its wait.
* A process a test starts — in its own process group, so a signal to the run's group misses it — ends with the
  test run even when pytest is SIGKILLed (tests/conftest.py's reaper).
"""
from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from isolation import DOMAIN_IDS, LOCK_DIR, NEXT_DOMAIN, domain_unused, realtime_slot

TESTS = Path(__file__).resolve().parent

CLAIM = textwrap.dedent("""
    import json, sys, time
    sys.path.insert(0, sys.argv[1])
    from isolation import claim_domain, claim_udp_port
    print(json.dumps({"domain": claim_domain(), "ports": [claim_udp_port() for _ in range(3)]}), flush=True)
    sys.stdin.read()  # hold the claims until told to go
""")


def claims(n: int, env: dict | None = None) -> tuple[list[dict], list[subprocess.Popen]]:
    procs = [subprocess.Popen([sys.executable, "-c", CLAIM, str(TESTS)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                              text=True, env=env) for _ in range(n)]
    out = [json.loads(p.stdout.readline()) for p in procs]  # type: ignore[union-attr]
    return out, procs


def release(procs: list[subprocess.Popen]) -> None:
    for p in procs:
        p.stdin.close()  # type: ignore[union-attr]
        p.wait(timeout=10)


def test_concurrent_runs_claim_different_domains_and_ports() -> None:
    held, procs = claims(4)
    try:
        domains = [h["domain"] for h in held]
        ports = [port for h in held for port in h["ports"]]
        assert len(set(domains)) == 4 and all(d in DOMAIN_IDS for d in domains)
        assert int(os.environ["ROS_DOMAIN_ID"]) not in domains  # and none is this run's own
        assert len(set(ports)) == len(ports)
    finally:
        release(procs)
    again, procs = claims(1)  # released with the processes: free for the next run
    release(procs)
    assert again[0]["domain"] in DOMAIN_IDS


ONE_CLAIM = textwrap.dedent("""
    import json, sys
    sys.path.insert(0, sys.argv[1])
    from isolation import claim_domain, release_domain
    domain = claim_domain()
    release_domain(domain)
    print(json.dumps(domain))
""")


def claimed_alone(locks: Path) -> int:
    """The domain a new process claims (and releases) with ``locks`` as its temporary folder: a lock folder of the
    test's own, which no other test run's claims change meanwhile."""
    out = subprocess.run([sys.executable, "-c", ONE_CLAIM, str(TESTS)], capture_output=True, text=True, timeout=30,
                         check=True, env={**os.environ, "TMPDIR": str(locks)})
    return int(json.loads(out.stdout))


def after(domain: int, steps: int = 1) -> int:
    return DOMAIN_IDS[(DOMAIN_IDS.index(domain) + steps) % len(DOMAIN_IDS)]


def quiet_turn(locks: Path, count: int) -> int:
    """Point the turn of the lock folder ``locks`` at a domain that begins ``count`` unused ones, half a round
    ahead of the machine's turn (which the other test runs' claims move on: their participants are behind it),
    and return that domain; skips the test if there is none."""
    counter = LOCK_DIR / NEXT_DOMAIN
    text = counter.read_text(encoding="utf-8").strip() if counter.exists() else ""
    machine = int(text) if text.isdigit() else 0
    for offset in range(len(DOMAIN_IDS) // 2, len(DOMAIN_IDS)):
        index = (machine + offset) % len(DOMAIN_IDS)
        if all(domain_unused(DOMAIN_IDS[(index + k) % len(DOMAIN_IDS)]) for k in range(count)):
            (locks / LOCK_DIR.name).mkdir(parents=True, exist_ok=True)
            (locks / LOCK_DIR.name / NEXT_DOMAIN).write_text(str(index), encoding="utf-8")
            return DOMAIN_IDS[index]
    pytest.skip(reason=f"no {count} unused domains in a row on this host")


def test_the_processes_of_the_machine_claim_the_domains_in_turn(tmp_path: Path) -> None:
    # each test claims a domain and releases it after: the next claim, of any process, is the next domain, so a
    # participant an earlier test left behind (ending, or leaked) meets a later test only a whole round later
    start = quiet_turn(tmp_path, 3)
    claims = [claimed_alone(tmp_path) for _ in range(3)]  # three processes: each its own pid, the machine's turn
    assert claims == [start, after(start), after(start, 2)]


@pytest.mark.parametrize("offset", [0, 10], ids=["multicast", "unicast-participant-0"])
def test_a_domain_whose_discovery_port_is_in_use_is_skipped(tmp_path: Path, offset: int) -> None:
    # a process holding a discovery port of the next domain in turn (7400 + 250 id: Cyclone's SPDP multicast, Fast
    # DDS; 7410 + 250 id: the first participant's unicast port, Fast DDS and Cyclone with participant indices)
    # without a lock: a leftover graph
    domain = quiet_turn(tmp_path, 2)
    squatter = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        squatter.bind(("127.0.0.1", 7400 + offset + 250 * domain))
    except OSError:
        squatter.close()
        pytest.skip(reason=f"the discovery port of domain {domain} was taken meanwhile")
    try:
        assert claimed_alone(tmp_path) == after(domain)  # skipped
    finally:
        squatter.close()


SEEN_DOMAINS: list[int] = []


@pytest.mark.parametrize("case", ["one", "other"])
def test_each_test_has_a_domain_of_its_own(case: str, dds_domain: int, dds_module_domain: int) -> None:
    assert os.environ["ROS_DOMAIN_ID"] == str(dds_domain) and dds_domain != dds_module_domain
    assert dds_domain not in SEEN_DOMAINS, case  # the other case (before this one, in either order) had another
    SEEN_DOMAINS.append(dds_domain)
    held, procs = claims(2)  # locked while the test runs: another process is given other domains
    release(procs)
    assert dds_domain not in [h["domain"] for h in held]


INNER = textwrap.dedent('''
    import os, subprocess, sys, time
    from pathlib import Path

    def test_starts_a_node_and_hangs():
        node = subprocess.Popen([sys.executable, "-m", "moose_ros.nodes", "observer"], start_new_session=True,
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        Path(os.environ["PID_FILE"]).write_text(str(node.pid))
        time.sleep(600)
''')


def alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split(") ")[-1][0] != "Z"  # a zombie has ended
    except OSError:
        return False


@pytest.mark.graph
def test_a_node_started_by_a_test_ends_when_pytest_is_killed(tmp_path: Path) -> None:
    (tmp_path / "test_inner.py").write_text(INNER)
    pid_file = tmp_path / "node.pid"
    python_path = os.pathsep.join([str(TESTS), os.environ.get("PYTHONPATH", "")])
    env = dict(os.environ, PID_FILE=str(pid_file), PYTHONPATH=python_path)
    inner = subprocess.Popen([sys.executable, "-m", "pytest", "-q", "-p", "conftest", "-p", "no:randomly", "-p",
                              "no:cacheprovider", "--rootdir", str(tmp_path), str(tmp_path / "test_inner.py")],
                             cwd=tmp_path, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60.0
        while not pid_file.exists() or not pid_file.read_text():
            assert time.monotonic() < deadline and inner.poll() is None, "the inner test run did not start its node"
            time.sleep(0.1)
        node = int(pid_file.read_text())
        time.sleep(1.0)
        assert alive(node) and os.getpgid(node) != os.getpgid(inner.pid)  # its own process group
        inner.send_signal(signal.SIGKILL)
        inner.wait(timeout=10)
        deadline = time.monotonic() + 15.0
        while alive(node) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not alive(node), f"node {node} outlived the killed test run"
    finally:
        if inner.poll() is None:
            inner.kill()
            inner.wait()


HOLD = textwrap.dedent("""
    import sys
    sys.path.insert(0, sys.argv[1])
    from isolation import realtime_slot
    with realtime_slot(name=sys.argv[2]):
        print("held", flush=True)
        sys.stdin.read()  # until the test closes our stdin
""")


def test_the_real_time_slot_is_one_process_at_a_time() -> None:
    name = f"realtime-test-{os.getpid()}"  # not the real slot: a concurrent run's graph tests may hold that one
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(TESTS), name], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
        start = time.monotonic()
        with pytest.raises(RuntimeError, match="stayed held by another run for 0.5 s"):
            with realtime_slot(wait=0.5, name=name):
                pass
        assert time.monotonic() - start >= 0.5
        assert holder.stdin is not None
        holder.stdin.close()  # the holder lets go
        holder.wait(timeout=10)
        with realtime_slot(wait=10.0, name=name):
            with realtime_slot(wait=0.0, name=name):  # re-entrant in one process: no wait, no deadlock
                pass
    finally:
        if holder.poll() is None:
            holder.kill()
            holder.wait()
        (LOCK_DIR / name).unlink(missing_ok=True)


CONCURRENT = ["tests/test_ros_runtime.py", "tests/test_can_udp.py",
              "tests/test_fault_matrix.py::test_fault[full-vehicle_simulator-kill]"]
"""Nodes talking over DDS, CAN buses on UDP multicast and loopback ports, a whole graph launched and judged
(real-time slot): what two runs sharing a domain, a port or the cores would break."""


@pytest.mark.graph
@pytest.mark.slow
@pytest.mark.realtime(slot=False)  # its runs' real-time tests need the cores: the serial phase, not beside a worker
def test_two_test_runs_at_once_both_pass(tmp_path: Path) -> None:
    env = {k: v for k, v in os.environ.items() if k != "ROS_DOMAIN_ID"}  # each run claims its own
    runs = [subprocess.Popen([sys.executable, "-m", "pytest", "-q", "-p", "no:randomly", "-p", "no:cacheprovider",
                              "--basetemp", str(tmp_path / f"run{i}"), *CONCURRENT], cwd=TESTS.parent, env=env,
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True) for i in range(2)]
    try:
        outputs = [run.communicate(timeout=1200)[0] for run in runs]  # a concurrent suite may hold the slot
    finally:
        for run in runs:
            if run.poll() is None:
                run.kill()
                run.wait()
    for run, output in zip(runs, outputs):
        assert run.returncode == 0, output[-3000:]
        assert " passed" in output, output[-3000:]
