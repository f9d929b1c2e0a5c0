"""What ROS 2 tools and Foxglove see of a running ``moose launch`` (the Cyclone DDS path), checked by
clients that share no code with our runtime:

- a plain WebSocket client speaking the Foxglove WebSocket protocol to the live view (subprotocol
  ``foxglove.sdk.v1``, the protocol's current name, which foxglove-sdk 0.30 requires; older servers
  spoke ``foxglove.websocket.v1``, offered too): every channel of the graph contract advertised
  with its ROS 2 schema, odometry and TF received and decoded by rosbags' CDR, the server listening
  on the loopback address only;
- rclpy 7.1.6 on Fast DDS (ROS 2 Jazzy from the PyPI wheels), in a process of its own: every node of the
  graph with exactly the publishers and subscriptions of the graph contract
  (``get_node_names_and_namespaces``, ``get_publisher_names_and_types_by_node``,
  ``get_subscriber_names_and_types_by_node``), and on every topic each publisher's node and RIHS01 type
  hash (``get_publishers_info_by_topic``), compared with the hash rclpy's own publisher of that type
  carries (rosidl's computation, not rosbags').

The rclpy client needs a ROS 2 environment: ``MOOSE_ROS_PREFIX`` or ``.venv-ros`` made by ``make ros``
(its ``ros-env.json``), else ``MOOSE_RCLPY_PYTHON`` (an interpreter with ``ros-jazzy-rclpy[fastrtps]``
and the standard message wheels).  Without one the test is skipped and says why; with
``MOOSE_REQUIRE_ROS=1`` that is a failure.  Both vendors discover on this host only: the client with
ROS 2 Jazzy's ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``, the graph with the Cyclone configuration
rmw_cyclonedds makes of it.
"""
from __future__ import annotations

import json
import os
import re
import signal
import struct
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path
from typing import Any, Iterator, Optional

import pytest

from isolation import realtime_slot
from moose_ros.graph import GRAPHS, TOPICS, publishes, subscribes
from moose_ros.interfaces import type_hash, typestore

# the graph is paced in real time (rate 0.5) and holds the real-time slot: in the serial phase of make test
pytestmark = [pytest.mark.graph, pytest.mark.slow, pytest.mark.realtime, pytest.mark.dds_module_domain]

REPO = Path(__file__).resolve().parents[1]
NODES = [n for n in GRAPHS["full"]]  # the combined planner: both planners run
LOCALHOST_CYCLONE = (
    '<CycloneDDS><Domain Id="any"><General><Interfaces><NetworkInterface name="lo"/></Interfaces>'
    "<AllowMulticast>false</AllowMulticast></General><Discovery><ParticipantIndex>auto</ParticipantIndex>"
    '<MaxAutoParticipantIndex>32</MaxAutoParticipantIndex><Peers><Peer address="localhost"/></Peers>'
    "</Discovery></Domain></CycloneDDS>"
)


class Graph:
    """``moose launch`` with the live view on a free port, its output collected by a thread."""

    def __init__(self, proc: subprocess.Popen, lines: list[str]) -> None:
        self.proc, self.lines = proc, lines

    def url(self, limit: float = 60.0) -> str:
        deadline = time.monotonic() + limit
        while time.monotonic() < deadline:
            for line in list(self.lines):
                found = re.search(r"Foxglove live view on (ws://\S+)", line)
                if found:
                    return found.group(1)
            assert self.proc.poll() is None, "".join(self.lines[-30:])
            time.sleep(0.1)
        raise AssertionError("no live view announced:\n" + "".join(self.lines[-30:]))


@pytest.fixture(scope="module")
def graph(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Graph]:
    with realtime_slot():
        yield from _graph(tmp_path_factory)


def _graph(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Graph]:
    config = tmp_path_factory.mktemp("dds-localhost") / "cyclonedds.xml"
    config.write_text(LOCALHOST_CYCLONE)
    env = {**os.environ, "CYCLONEDDS_URI": config.as_uri(), "MOOSE_RUNTIME": "dds"}
    # rate 0.5: 9 s of simulated time last 18 s, a window for both clients
    proc = subprocess.Popen([sys.executable, "-m", "moose.cli", "launch", "--scenario", "paper_v7_tau1.4", "--no-bag",
                             "--rate", "0.5", "--foxglove", "0"], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, start_new_session=True)
    lines: list[str] = []

    def collect() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            lines.append(line)

    threading.Thread(target=collect, daemon=True).start()
    try:
        yield Graph(proc, lines)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGTERM)  # the launcher stops its nodes
            try:
                proc.wait(30)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()


# -- Foxglove ---------------------------------------------------------------------------------------

def _listening_addresses(port: int) -> set[str]:
    """Local addresses of TCP sockets listening on ``port`` (from /proc/net/tcp and tcp6)."""
    found = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        try:
            rows = Path(table).read_text().splitlines()[1:]
        except OSError:
            continue
        for row in rows:
            local, state = row.split()[1], row.split()[3]
            address, hexport = local.split(":")
            if int(hexport, 16) == port and state == "0A":  # LISTEN
                found.add(address)
    return found


def test_foxglove_client_sees_the_graph_and_receives_odometry(graph: Graph) -> None:
    import websocket

    url = graph.url()
    port = int(url.rsplit(":", 1)[1])
    assert url.startswith("ws://127.0.0.1:")
    assert _listening_addresses(port) == {"0100007F"}  # 127.0.0.1 only, not every interface
    ws = websocket.create_connection(url, subprotocols=["foxglove.sdk.v1", "foxglove.websocket.v1"],
                                     timeout=10)
    try:
        channels: dict[int, dict[str, Any]] = {}
        deadline = time.monotonic() + 20
        while set(c["topic"] for c in channels.values()) != set(TOPICS) and time.monotonic() < deadline:
            frame = ws.recv()
            if isinstance(frame, str):
                message = json.loads(frame)
                if message.get("op") == "advertise":
                    channels.update({c["id"]: c for c in message["channels"]})
        assert {c["topic"]: (c["encoding"], c["schemaName"], c["schemaEncoding"]) for c in channels.values()} == {
            t.name: ("cdr", t.type, "ros2msg") for t in TOPICS.values()}
        wanted = {c["id"]: c["topic"] for c in channels.values() if c["topic"] in ("/vehicle/odom", "/tf")}
        ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": cid, "channelId": cid} for cid in wanted]}))
        received: dict[str, list[Any]] = {"/vehicle/odom": [], "/tf": []}
        deadline = time.monotonic() + 60
        while min(len(v) for v in received.values()) < 50 and time.monotonic() < deadline:
            try:
                frame = ws.recv()
            except websocket.WebSocketTimeoutException:
                continue  # the simulator starts the clock once every node has loaded
            if isinstance(frame, bytes) and frame[0] == 0x01:  # MessageData: op, subscription id, time, payload
                subscription, _stamp = struct.unpack_from("<IQ", frame, 1)
                topic = wanted[subscription]
                received[topic].append(typestore().deserialize_cdr(frame[13:], TOPICS[topic].type))
    finally:
        ws.close()
    odom = received["/vehicle/odom"]
    assert len(odom) >= 50, {k: len(v) for k, v in received.items()}
    assert {(m.header.frame_id, m.child_frame_id) for m in odom} == {("odom", "base_link_truth")}
    xs = [m.pose.pose.position.x for m in odom]
    assert xs == sorted(xs) and xs[-1] > xs[0]  # the car drives forward
    frames = {(x.header.frame_id, x.child_frame_id) for m in received["/tf"] for x in m.transforms}
    assert frames == {("odom", "base_link"), ("odom", "base_link_truth")}


# -- rclpy ------------------------------------------------------------------------------------------

PROBE = textwrap.dedent(r'''
    import importlib, json, sys, time
    import rclpy
    expected, types, limit = set(json.loads(sys.argv[1])), json.loads(sys.argv[2]), float(sys.argv[3])
    counts = json.loads(sys.argv[5])  # node -> [publishers, subscriptions] of the graph contract
    rclpy.init()
    node = rclpy.create_node("moose_probe")
    deadline = time.monotonic() + limit

    def complete():  # every node up with at least the contract's endpoints (the test compares them exactly)
        names = {name: ns for name, ns in node.get_node_names_and_namespaces()}
        if not expected <= set(names):
            return False
        return all(len(node.get_publisher_names_and_types_by_node(name, names[name])) >= pubs
                   and len(node.get_subscriber_names_and_types_by_node(name, names[name])) >= subs
                   for name, (pubs, subs) in counts.items())

    while time.monotonic() < deadline and not complete():
        rclpy.spin_once(node, timeout_sec=0.2)
    out = {"nodes": sorted(node.get_node_names_and_namespaces()), "endpoints": {}, "topics": {}, "rclpy_hashes": {}}
    for name, ns in out["nodes"]:
        if name in expected:
            out["endpoints"][name] = {
                "publishers": sorted([t, sorted(k)] for t, k in node.get_publisher_names_and_types_by_node(name, ns)),
                "subscriptions": sorted([t, sorted(k)]
                                        for t, k in node.get_subscriber_names_and_types_by_node(name, ns)),
            }
    for topic in json.loads(sys.argv[4]):
        out["topics"][topic] = sorted([i.node_name, i.node_namespace, i.topic_type, str(i.topic_type_hash)]
                                      for i in node.get_publishers_info_by_topic(topic))
    for k, type_name in enumerate(types):  # the hash rclpy's own publisher of each type carries
        package, _, name = type_name.split("/")
        try:
            cls = getattr(importlib.import_module(package + ".msg"), name)
        except (ImportError, AttributeError):
            continue
        topic = f"/moose_probe/type_{k}"
        node.create_publisher(cls, topic, 1)
        info = node.get_publishers_info_by_topic(topic)
        out["rclpy_hashes"][type_name] = str(info[0].topic_type_hash) if info else None
    print(json.dumps(out))
    node.destroy_node()
    rclpy.shutdown()
''')


def _rclpy_environment() -> tuple[Optional[str], dict[str, str], str]:
    """(python, environment, why not) of a ROS 2 client: ``make ros``'s prefix, else ``MOOSE_RCLPY_PYTHON``."""
    prefix = Path(os.environ.get("MOOSE_ROS_PREFIX") or REPO / ".venv-ros")
    base = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "AMENT_PREFIX_PATH", "CYCLONEDDS_URI")}
    base.update(ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", RMW_IMPLEMENTATION="rmw_fastrtps_cpp")
    spec = prefix / "ros-env.json"
    if spec.is_file():
        values = json.loads(spec.read_text(encoding="utf-8"))
        env = {**base, **values["set"]}
        for name, parts in values["prepend"].items():
            env[name] = os.pathsep.join(parts + ([env[name]] if env.get(name) else []))
        return env["MOOSE_ROS_PYTHON"], env, ""
    python = os.environ.get("MOOSE_RCLPY_PYTHON")
    if python:
        return python, base, ""
    return None, base, (f"no ROS 2 client: {spec} is missing (make ros) and MOOSE_RCLPY_PYTHON is not set "
                        "(a Python with ros-jazzy-rclpy[fastrtps] and the ros-jazzy-*-msgs wheels)")


def test_rclpy_sees_every_node_its_endpoints_and_type_hashes(graph: Graph) -> None:
    python, env, why = _rclpy_environment()
    if python is not None:
        check = subprocess.run([python, "-c", "import rclpy, nav_msgs.msg"], env=env, capture_output=True, text=True,
                               timeout=60)
        if check.returncode != 0:
            python, why = None, f"{python} cannot import rclpy: {check.stderr.strip().splitlines()[-1:]}"
    if python is None:
        if os.environ.get("MOOSE_REQUIRE_ROS") == "1":
            pytest.fail(why)
        pytest.skip(why)
    graph.url()  # the launcher is up; its nodes are starting
    types = sorted({t.type for t in TOPICS.values()})
    counts = {name: [len(publishes(name)), len(subscribes(name))] for name in NODES}
    probe = subprocess.run([python, "-c", PROBE, json.dumps(NODES + ["moose_monitor"]), json.dumps(types), "60",
                            json.dumps(sorted(TOPICS)), json.dumps(counts)], env=env, capture_output=True, text=True,
                           timeout=120)
    assert probe.returncode == 0, probe.stderr[-3000:]
    seen = json.loads(probe.stdout.strip().splitlines()[-1])
    names = {name for name, ns in seen["nodes"]}
    assert set(NODES) | {"moose_monitor"} <= names, f"missing {set(NODES) - names}"
    assert all(ns == "/" for name, ns in seen["nodes"])
    for name in NODES:  # exactly the graph contract's endpoints (the runtime's /clock reader included)
        endpoints = seen["endpoints"][name]
        assert endpoints["publishers"] == sorted([t.name, [t.type]] for t in publishes(name)), name
        assert endpoints["subscriptions"] == sorted([t.name, [t.type]] for t in subscribes(name)), name
    checked_with_rclpy = set()
    for topic, infos in seen["topics"].items():
        contract = TOPICS[topic]
        assert {i[0] for i in infos} - {"moose_monitor"} == set(contract.publishers) & set(NODES), topic
        for _node, _ns, topic_type, hash_ in infos:
            assert topic_type == contract.type and hash_ == type_hash(contract.type), (topic, hash_)
            theirs = seen["rclpy_hashes"].get(contract.type)
            if theirs is not None:
                assert hash_ == theirs, (topic, contract.type)
                checked_with_rclpy.add(contract.type)
    # every standard type the client has, and moose_msgs' and tf2_msgs' when `make ros` built them (no wheel
    # carries tf2_msgs; test_ros_introspection.py also checks its hash against Jazzy's published value)
    importable = {t for t, h in seen["rclpy_hashes"].items() if h}
    assert {"nav_msgs/msg/Odometry", "sensor_msgs/msg/Imu", "rosgraph_msgs/msg/Clock",
            "diagnostic_msgs/msg/DiagnosticArray", "visualization_msgs/msg/MarkerArray"} <= importable
    if any(t.startswith("moose_msgs/") for t in importable):
        assert "tf2_msgs/msg/TFMessage" in importable
    assert checked_with_rclpy == importable & {t.type for t in TOPICS.values()}
