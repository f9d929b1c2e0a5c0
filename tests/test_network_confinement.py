"""The graph is confined to its host by default, on both runtimes, tested from outside: a second network namespace
stands in for another host on the same network.

Two network namespaces joined by a veth pair (created here and removed afterwards, also on failure).  In
namespace A, ``moose node can_bridge`` runs with its defaults (no ROS_DOMAIN_ID, no CYCLONEDDS_URI, no
discovery variables: domain 0 of that namespace) on Cyclone DDS or on rclpy (Fast DDS, the Jazzy wheels of
``make ros``), and a listener decodes the command frames it puts on the ``udp_multicast`` bus with cantools and
the DBC.  From namespace B, participants publish 0.3 rad of steering and 200 N·m per motor on
``/control/actuator_command``: plain Cyclone DDS participants (the wire format of a ROS 2 node: ``rt/`` topic,
``pkg::msg::dds_::Type_``, XCDR1) with Cyclone's defaults (multicast discovery) and with namespace A's address as
a unicast peer (an attacker who knows the car computer's address), and a plain rclpy node on Fast DDS with
``ROS_STATIC_PEERS`` naming namespace A (the probe that reached the rclpy bridge: 2,401 frames, up to 0.3 rad and
200 N·m).  None may match the bridge, no commanded steering may reach the bus, and on rclpy no socket of the
bridge may be bound to anything but 127.0.0.1 (and the bus's multicast group, joined on loopback); a publisher in
namespace A on the runtime's defaults then does reach the bus (the bridge was reachable from its own host all
along).  With ``ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET`` (the opt-in) the publisher from B does reach the bus, and
so does one on a host named in ``ROS_STATIC_PEERS``, so the test can fail.
"""
from __future__ import annotations

import contextlib
import ipaddress
import json
import os
import queue
import secrets
import shutil
import signal
import struct
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path
from typing import Iterator, Optional

import pytest

pytestmark = [pytest.mark.graph, pytest.mark.can, pytest.mark.slow]

DDS_VARIABLES = ("ROS_DOMAIN_ID", "CYCLONEDDS_URI", "ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_STATIC_PEERS",
                 "ROS_LOCALHOST_ONLY")
"""What the test run sets for its own isolation (tests/conftest.py); removed so the bridge runs on its defaults."""
ATTACK_S = 4.0
"""How long a publisher that must not be matched sends (s): Cyclone DDS discovery on a quiet link takes well
under a second."""
REACH_S = 60.0
"""How long a publisher that must reach the bus may take to (s): it sends until the bus shows its command."""
START_TIMEOUT = 60.0

PUBLISHER = textwrap.dedent("""
    import json, sys, time
    import threading
    mode, config, duration = sys.argv[1], sys.argv[2], float(sys.argv[3])
    done = threading.Event()  # the test closes our stdin when the bus has shown our command
    threading.Thread(target=lambda: (sys.stdin.read(), done.set()), daemon=True).start()
    steer, torque = 0.3, 200.0
    if mode == "rclpy":  # a plain rclpy node (Fast DDS), not our runtime: ROS 2's own settings
        import rclpy
        from moose_msgs.msg import ActuatorCommand
        rclpy.init()
        node = rclpy.create_node("intruder")
        pub = node.create_publisher(ActuatorCommand, "/control/actuator_command", 10)
        make = lambda: ActuatorCommand(steering_angle=steer, torque_rl=torque, torque_rr=torque)
        write, matched = pub.publish, pub.get_subscription_count
    elif mode == "runtime":  # our runtime on its defaults
        from moose_ros.graph import ACTUATOR_COMMAND
        from moose_ros.runtime import create_node
        node = create_node("intruder")
        pub = ACTUATOR_COMMAND.publisher(node)
        make = lambda: node.make(ACTUATOR_COMMAND.type, steering_angle=steer, torque_rl=torque, torque_rr=torque)
        write, matched = pub, pub.subscription_count
    else:  # a plain Cyclone DDS participant speaking ROS 2's wire format
        from cyclonedds.core import Policy, Qos
        from cyclonedds.domain import Domain, DomainParticipant
        from cyclonedds.pub import DataWriter
        from cyclonedds.topic import Topic
        from moose_ros.interfaces import message_class
        domain = Domain(0, config) if config else None
        participant = DomainParticipant(0)
        cls = message_class("moose_msgs/msg/ActuatorCommand")
        qos = Qos(Policy.Reliability.Reliable(10**8), Policy.History.KeepLast(10),
                  Policy.DataRepresentation(use_cdrv0_representation=True))
        writer = DataWriter(participant, Topic(participant, "rt/control/actuator_command", cls), qos=qos)
        make = lambda: cls(steering_angle=steer, torque_rl=torque, torque_rr=torque)
        write, matched = writer.write, lambda: len(writer.get_matched_subscriptions())
    start, best, first = time.monotonic(), 0, None
    while time.monotonic() - start < duration and not done.is_set():
        msg = make()
        now = time.time()
        msg.header.stamp.sec, msg.header.stamp.nanosec = int(now), int((now % 1) * 1e9)
        write(msg)
        count = matched()
        if count and first is None:
            first = time.monotonic() - start
        best = max(best, count)
        time.sleep(0.01)
    print(json.dumps({"matched": best, "first_match_s": first}), flush=True)
""")

LISTENER = textwrap.dedent("""
    import json, sys, threading, time
    from moose.canbus.bus import DEFAULT_GROUP, DEFAULT_PORT, open_bus
    from moose.canbus.codec import default_database
    db, duration = default_database(), float(sys.argv[1])
    done = threading.Event()  # the test closes our stdin when the publishers have ended
    threading.Thread(target=lambda: (sys.stdin.read(), done.set()), daemon=True).start()
    bus = open_bus("udp_multicast", DEFAULT_GROUP, DEFAULT_PORT)
    print("ready", flush=True)
    frames, steer, torque, start, commanded = 0, 0.0, 0.0, time.monotonic(), False
    while time.monotonic() - start < duration and not done.is_set():
        frame = bus.recv(timeout=0.05)
        if frame is None or frame.arbitration_id not in (0x100, 0x101):
            continue
        frames += 1
        values = db.decode_message(frame.arbitration_id, bytes(frame.data))
        steer = max(steer, abs(values.get("SteerAngleCmd", 0.0)))
        torque = max(torque, abs(values.get("TorqueRL", 0.0)), abs(values.get("TorqueRR", 0.0)))
        if steer > 0.29 and torque > 100.0 and not commanded:  # the steering and torque commanded from outside
            commanded = True
            print("commanded", flush=True)
    bus.shutdown()
    print(json.dumps({"command_frames": frames, "max_steer": steer, "max_torque": torque}), flush=True)
""")


BUS_GROUP = "239.74.163.2"
"""moose.canbus.bus.DEFAULT_GROUP: the bridge's bus socket is bound to it (joined on loopback, TTL 0)."""


def _ip(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], capture_output=True, text=True, timeout=15)


class Hosts:
    """Two network namespaces ``a`` and ``b`` joined by a veth pair (10.231.x.1 in a, .2 in b)."""

    def __init__(self) -> None:
        tag = f"{os.getpid() % 100000}{secrets.token_hex(2)}"
        self.a, self.b = f"moose-{tag}-a", f"moose-{tag}-b"
        self.veth = (f"mv{tag}a", f"mv{tag}b")
        subnet = f"10.231.{secrets.randbelow(250) + 1}"
        self.addr_a, self.addr_b = f"{subnet}.1", f"{subnet}.2"
        self.procs: list[subprocess.Popen] = []

    def create(self) -> None:
        made = _ip("netns", "add", self.a)
        if made.returncode != 0:
            pytest.skip(f"cannot create a network namespace (needs CAP_SYS_ADMIN/CAP_NET_ADMIN): {made.stderr.strip()}")
        steps = [("netns", "add", self.b),
                 ("link", "add", self.veth[0], "type", "veth", "peer", "name", self.veth[1]),
                 ("link", "set", self.veth[0], "netns", self.a), ("link", "set", self.veth[1], "netns", self.b),
                 ("-n", self.a, "addr", "add", f"{self.addr_a}/24", "dev", self.veth[0]),
                 ("-n", self.b, "addr", "add", f"{self.addr_b}/24", "dev", self.veth[1])]
        steps += [("-n", ns, "link", "set", dev, "up") for ns in (self.a, self.b) for dev in ("lo",)]
        steps += [("-n", self.a, "link", "set", self.veth[0], "up"), ("-n", self.b, "link", "set", self.veth[1], "up")]
        for step in steps:
            done = _ip(*step)
            assert done.returncode == 0, f"ip {' '.join(step)}: {done.stderr.strip()}"

    def remove(self) -> None:
        for proc in self.procs:
            stop(proc)
        _ip("link", "del", self.veth[0])  # only if it never moved into a namespace
        for ns in (self.a, self.b):
            _ip("netns", "del", ns)

    def spawn(self, ns: str, args: list[str], env_extra: Optional[dict[str, str]] = None,
              base: Optional[dict[str, str]] = None) -> subprocess.Popen:
        env = {k: v for k, v in (os.environ if base is None else base).items() if k not in DDS_VARIABLES}
        env.update(env_extra or {})
        proc = subprocess.Popen(["ip", "netns", "exec", ns, *args], env=env, stdin=subprocess.PIPE,
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True)
        self.procs.append(proc)
        return proc


def stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        pass


@pytest.fixture(scope="module")
def hosts() -> Iterator[Hosts]:
    if shutil.which("ip") is None:
        pytest.skip("no `ip` command (iproute2): cannot create network namespaces")
    pair = Hosts()
    try:
        pair.create()
        yield pair
    finally:
        pair.remove()
    listed = _ip("netns", "list").stdout
    assert pair.a not in listed and pair.b not in listed, "a namespace of the test survived it"


class Lines:
    """The output lines of a process, read by a thread (so waiting for one is bounded in time)."""

    def __init__(self, proc: subprocess.Popen) -> None:
        self.proc, self.lines, self.queue = proc, [], queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.append(line)
            self.queue.put(line)
        self.queue.put(None)

    def saw(self, text: str, timeout: float) -> bool:
        """Whether the process prints a line holding ``text`` within ``timeout`` s."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                line = self.queue.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                break
            if line is None:
                break
            if text in line:
                return True
        return False

    def wait_for(self, text: str, timeout: float) -> None:
        if not self.saw(text, timeout):
            raise AssertionError(f"no {text!r} within {timeout} s; output:\n{''.join(self.lines)}")

    def end(self) -> None:
        """Close the process's stdin: a listener, or a publisher that reaches the bus, ends then."""
        if self.proc.stdin is not None and not self.proc.stdin.closed:
            self.proc.stdin.close()

    def result(self, timeout: float) -> dict:
        """The JSON line the process printed last, once it has ended."""
        try:
            self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            stop(self.proc)
        time.sleep(0.1)
        for line in reversed(self.lines):
            if line.startswith("{"):
                return json.loads(line)
        raise AssertionError(f"no result; output:\n{''.join(self.lines)}")


@pytest.fixture(params=["dds", "rclpy"])
def runtime(request: pytest.FixtureRequest) -> tuple[str, str, dict[str, str]]:
    """(runtime, interpreter, environment) of the bridge and of the publishers on that runtime: this interpreter
    for Cyclone DDS; the ROS 2 prefix of ``make ros`` for rclpy (skipped, saying why, when it is not made)."""
    if request.param == "dds":
        return "dds", sys.executable, {**os.environ, "MOOSE_RUNTIME": "dds"}
    env = request.getfixturevalue("ros_env")
    return "rclpy", env["MOOSE_ROS_PYTHON"], {**env, "MOOSE_RUNTIME": "rclpy"}


def start_bridge(hosts: Hosts, runtime: tuple[str, str, dict[str, str]],
                 env: Optional[dict[str, str]] = None) -> Lines:
    _name, python, base = runtime
    bridge = Lines(hosts.spawn(hosts.a, [python, "-m", "moose.cli", "node", "can_bridge"], env, base))
    bridge.wait_for("can_bridge started", START_TIMEOUT)
    return bridge


def attack(hosts: Hosts, ns: str, mode: str, config: str = "", env: Optional[dict[str, str]] = None,
           runtime: Optional[tuple[str, str, dict[str, str]]] = None) -> Lines:
    """A publisher of 0.3 rad and 200 N·m in namespace ``ns``, for ATTACK_S."""
    python, base = (sys.executable, None) if runtime is None else runtime[1:]
    return Lines(hosts.spawn(ns, [python, "-c", PUBLISHER, mode, config, str(ATTACK_S)], env, base))


def reach(hosts: Hosts, bus: Lines, ns: str, mode: str, config: str = "", env: Optional[dict[str, str]] = None,
          runtime: Optional[tuple[str, str, dict[str, str]]] = None) -> tuple[dict, dict]:
    """A publisher that must reach the bus (the check that the test can fail): it sends until the bus listener has
    decoded its command, or for REACH_S; then (publisher's result, listener's result)."""
    python, base = (sys.executable, None) if runtime is None else runtime[1:]
    publisher = Lines(hosts.spawn(ns, [python, "-c", PUBLISHER, mode, config, str(REACH_S)], env, base))
    bus.saw("commanded", REACH_S + START_TIMEOUT)
    publisher.end()
    sent = publisher.result(30)
    bus.end()
    return sent, bus.result(30)


def listen(hosts: Hosts) -> Lines:
    """A decoder of the bus's command frames in namespace a, until its result is asked for (Lines.result), once
    the publishers have ended."""
    listener = Lines(hosts.spawn(hosts.a, [sys.executable, "-c", LISTENER, str(REACH_S + START_TIMEOUT)]))
    listener.wait_for("ready", START_TIMEOUT)
    return listener


def unicast_peer(address: str) -> str:
    return (f'<CycloneDDS><Domain><Discovery><Peers><Peer address="{address}"/></Peers>'
            "<ParticipantIndex>auto</ParticipantIndex></Discovery></Domain></CycloneDDS>")


def udp_addresses(pid: int) -> set[str]:
    """The local addresses of the UDP sockets process ``pid`` holds (its network namespace's /proc tables)."""
    inodes = set()
    for fd in os.listdir(f"/proc/{pid}/fd"):
        with contextlib.suppress(OSError):
            target = os.readlink(f"/proc/{pid}/fd/{fd}")
            if target.startswith("socket:["):
                inodes.add(target[len("socket:["):-1])
    found = set()
    for table in ("udp", "udp6"):
        for line in Path(f"/proc/{pid}/net/{table}").read_text().splitlines()[1:]:
            fields = line.split()
            if fields[9] in inodes:
                words = fields[1].split(":")[0]
                packed = b"".join(struct.pack("=I", int(words[i:i + 8], 16)) for i in range(0, len(words), 8))
                found.add(str(ipaddress.ip_address(packed)))
    return found


EXPECTED_LINE = {
    "dds": "DDS discovery LOCALHOST: this host only, Cyclone DDS on the loopback interface)",
    "rclpy": "DDS discovery LOCALHOST: this host only, Fast DDS bound to loopback (fastdds_loopback.xml); ",
}
"""What the bridge logs about its discovery on its defaults, per runtime."""


def test_the_bridge_on_its_defaults_cannot_be_reached_from_another_host(
        hosts: Hosts, runtime: tuple[str, str, dict[str, str]]) -> None:
    bridge = start_bridge(hosts, runtime)
    try:
        sockets = udp_addresses(bridge.proc.pid)
        bus = listen(hosts)
        remote = [attack(hosts, hosts.b, "plain"), attack(hosts, hosts.b, "plain", unicast_peer(hosts.addr_a))]
        if runtime[0] == "rclpy":  # the probe's attacker: ROS 2 on Fast DDS naming the car computer as its peer
            remote.append(attack(hosts, hosts.b, "rclpy", env={"ROS_STATIC_PEERS": hosts.addr_a}, runtime=runtime))
        results = [r.result(ATTACK_S + 30) for r in remote]
        bus.end()
        frames = bus.result(ATTACK_S + 30)
        assert [r["matched"] for r in results] == [0] * len(remote), results  # no discovery from the other host
        assert frames["command_frames"] > 100 and frames["max_steer"] == 0.0 and frames["max_torque"] == 0.0, frames
        # the same commands from the bridge's own host, on the runtime's defaults, do reach the bus
        local, frames = reach(hosts, listen(hosts), hosts.a, "runtime", runtime=runtime)
        assert local["matched"] >= 1, local
        assert frames["max_steer"] == pytest.approx(0.3, abs=1e-3) and frames["max_torque"] > 100.0, frames
    finally:
        stop(bridge.proc)
    assert EXPECTED_LINE[runtime[0]] in "".join(bridge.lines), "".join(bridge.lines)
    assert hosts.addr_a not in sockets, sockets  # no socket bound to the address the other host can reach
    if runtime[0] == "rclpy":  # on Fast DDS, every socket on loopback (Cyclone DDS listens on 0.0.0.0: Trust model)
        assert sockets and sockets <= {"127.0.0.1", BUS_GROUP}, sockets


@pytest.mark.parametrize("opt_in", ["subnet", "static_peer"])
def test_the_opt_in_reaches_the_bridge_from_another_host(hosts: Hosts, runtime: tuple[str, str, dict[str, str]],
                                                         opt_in: str) -> None:
    """``SUBNET``: multicast discovery on the link; ``ROS_STATIC_PEERS``: the named host only (unicast)."""
    if opt_in == "subnet":
        env, config = {"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"}, ""
    else:
        env, config = {"ROS_STATIC_PEERS": hosts.addr_b}, unicast_peer(hosts.addr_a)
    bridge = start_bridge(hosts, runtime, env)
    try:
        remote, frames = reach(hosts, listen(hosts), hosts.b, "plain", config)
    finally:
        stop(bridge.proc)
    assert remote["matched"] >= 1, remote
    assert frames["max_steer"] == pytest.approx(0.3, abs=1e-3) and frames["max_torque"] > 100.0, frames
    assert "bound to loopback" not in "".join(bridge.lines) and "loopback interface" not in "".join(bridge.lines)
