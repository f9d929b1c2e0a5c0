"""The node graph on real rclpy (ROS 2 Jazzy, Fast DDS, from ``make ros``), and mixed with our Cyclone runtime.

- All on rclpy: ``moose launch --runtime rclpy`` run by the prefix's interpreter, as a user in a
  ``. .venv-ros/setup.sh`` shell would (the monitor and the bag recorder are rclpy too).  A separate
  rclpy process, knowing nothing of our code, checks what a ROS 2 user sees meanwhile: node names,
  topics and types, each endpoint's node, QoS and type hash (against rosbags' RIHS01 hash of the
  ``.msg`` files), parameters through the nodes' ``rcl_interfaces`` services, and samples on
  ``/vehicle/odom`` and ``/vehicle/imu``.
- Mixed: the simulator and observer on rclpy/Fast DDS, the detector, planners, weight function and
  controller on Cyclone DDS, and the launcher's monitor on Cyclone: sensor data, the state estimate,
  the lockstep markers, the obstacle (transient local) and diagnostics cross from Fast DDS to Cyclone, the
  actuator commands, the markers and the nodes' start-up diagnostics (transient local) from Cyclone to Fast DDS.

Both graphs run in lockstep (``moose launch --lockstep``) on the extreme case (7 m/s, τ = 1.4 s) and are held
to what ``moose simulate`` computes with the same timing (tests/lockstep_reference.py): these tests check that the
graph computes the same thing on rclpy, not how fast (that is ``bench/bench_graph.py``'s and
``bench/bench_realtime.py``'s job).  What a ROS 2 user sees of the graph (names, types, QoS, parameters, samples)
is checked on a real-time run, which asserts only what holds under load: it starts, runs, stops and reports.
Every process is on loopback (``tests/ros2_prefix.py``) in the test run's domain and bounded in time.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Any

import pytest

from lockstep_reference import assert_reproduces, reference
from moose.scenario import load_scenario
from moose_ros.graph import FRAME_IMU, FRAME_ODOM, FRAME_TRUTH, GRAPHS, TOPICS
from moose_ros.interfaces import typestore
from moose_ros.launch import node_overrides

pytestmark = [pytest.mark.graph, pytest.mark.slow]

SCENARIO = "paper_v7_tau2"
"""The real-time run's case (2.0 m of clearance: what it shows does not depend on a race)."""
EXTREME = "paper_v7_tau1.4"
"""The lockstep runs' case."""
LIMIT = 240.0
"""Seconds a graph run may take here (about 30–60 s: start-up, then 9 simulated seconds)."""

PROBE = textwrap.dedent(r'''
    import json, sys, time
    import rclpy
    from rclpy.qos import qos_profile_sensor_data
    from rcl_interfaces.srv import GetParameters, ListParameters
    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import Imu

    expected, topics, queries = json.loads(sys.argv[1]), json.loads(sys.argv[2]), json.loads(sys.argv[3])
    limit = float(sys.argv[4])
    rclpy.init()
    node = rclpy.create_node("ros2_user_probe")
    samples = {"/vehicle/odom": [], "/vehicle/imu": []}
    stamp = lambda m: m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec
    node.create_subscription(Odometry, "/vehicle/odom", lambda m: samples["/vehicle/odom"].append(
        [stamp(m), m.header.frame_id, m.child_frame_id, m.pose.pose.position.x]), qos_profile_sensor_data)
    node.create_subscription(Imu, "/vehicle/imu", lambda m: samples["/vehicle/imu"].append(
        [stamp(m), m.header.frame_id, "", m.linear_acceleration.x]), qos_profile_sensor_data)
    deadline = time.monotonic() + limit
    spin = lambda: rclpy.spin_once(node, timeout_sec=0.05)

    def endpoints(infos):
        return sorted([i.node_name, i.node_namespace, i.topic_type, str(i.topic_type_hash),
                       i.qos_profile.reliability.name, i.qos_profile.durability.name] for i in infos)

    def graph():
        return {t: {"publishers": endpoints(node.get_publishers_info_by_topic(t)),
                    "subscriptions": endpoints(node.get_subscriptions_info_by_topic(t))} for t in topics}

    def settled():  # every node is there, and every endpoint carries its node's name (ros_discovery_info)
        names = {n for n, ns in node.get_node_names_and_namespaces()}
        return set(expected) <= names and "_NODE_NAME_UNKNOWN_" not in json.dumps(graph())

    while time.monotonic() < deadline and not (settled() and all(len(s) >= 100 for s in samples.values())):
        spin()
    report = {"nodes": sorted(node.get_node_names_and_namespaces()), "topics": dict(node.get_topic_names_and_types()),
              "graph": graph(), "parameters": {}}
    for target, names in queries.items():  # through the node's rcl_interfaces services, as `ros2 param` does
        get = node.create_client(GetParameters, f"/{target}/get_parameters")
        listed = node.create_client(ListParameters, f"/{target}/list_parameters")
        if not (get.wait_for_service(timeout_sec=10.0) and listed.wait_for_service(timeout_sec=10.0)):
            report["parameters"][target] = "no parameter services"
            continue
        values = get.call_async(GetParameters.Request(names=names))
        every = listed.call_async(ListParameters.Request())
        while time.monotonic() < deadline and not (values.done() and every.done()):
            spin()
        kinds = {1: "bool_value", 2: "integer_value", 3: "double_value", 4: "string_value", 9: "string_array_value"}
        report["parameters"][target] = {
            "values": {n: (getattr(v, kinds[v.type]) if v.type in kinds else None)
                       for n, v in zip(names, values.result().values)},
            "names": sorted(every.result().result.names)}
    report["samples"] = samples
    print(json.dumps(report, default=list), flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
''')

MIXED = textwrap.dedent(r'''
    import io, json, sys
    from moose.scenario import load_scenario
    from moose_ros.launch import launch
    out = io.StringIO()
    summary = launch(load_scenario(sys.argv[1]), {"scenario": sys.argv[1]}, out=out, bag=sys.argv[3],
                     runtime=json.loads(sys.argv[2]), lockstep=True)
    print(out.getvalue())
    print(json.dumps(summary))
''')


def run(cmd: list[str], env: dict[str, str], timeout: float) -> subprocess.CompletedProcess:
    """Run a command in a session of its own; on timeout its whole process group is killed."""
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, err = proc.communicate()
        pytest.fail(f"{cmd[:4]} did not finish in {timeout} s: {err[-3000:]}")
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    return subprocess.CompletedProcess(cmd, proc.returncode, out, err)


def check_ran(summary: dict[str, Any], log: str) -> None:
    """A real-time run started, ran, stopped and reported (what holds under load); ``log`` is the launcher's output
    (a node that outlived the launcher's grace wrote its stacks there)."""
    assert summary["outcome"] in ("clear", "collision", "left_field", "lost_control", "stopped_short")
    assert summary["odom_samples"] > 100  # simulated time ran, seen by the monitor
    # the simulator finished; every other node ran until the launcher stopped it (SIGTERM: rclpy exits 0,
    # a Cyclone node is ended by the signal)
    assert summary["node_exits"]["vehicle_simulator"] == 0
    assert set(summary["node_exits"].values()) <= {0, -signal.SIGTERM}, (summary["node_exits"], log[-6000:])


def read_odometry(bag: Path) -> list[tuple[float, float]]:
    """(t, y) of every /vehicle/odom message of a bag, read with rosbags alone."""
    from rosbags.highlevel import AnyReader

    with AnyReader([bag]) as reader:
        connections = [c for c in reader.connections if c.topic == "/vehicle/odom"]
        rows = []
        for connection, _stamp, raw in reader.messages(connections=connections):
            msg = reader.deserialize(raw, connection.msgtype)
            rows.append((msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec, msg.pose.pose.position.y))
    return sorted(rows)


def test_full_graph_on_rclpy_reproduces_the_lockstep_loop(ros_env: dict[str, str], tmp_path: Path) -> None:
    result = run([ros_env["MOOSE_ROS_PYTHON"], "-m", "moose.cli", "launch", "--runtime", "rclpy", "--scenario",
                  EXTREME, "--lockstep", "--json", str(tmp_path / "summary.json"), "--no-bag"], ros_env, LIMIT)
    assert result.returncode == 0, (result.stdout + result.stderr)[-3000:]  # the summary says why
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["runtime"] == {**{n: "rclpy" for n in GRAPHS["full"]}, "moose_monitor": "rclpy"}
    assert not summary["degraded"] and summary["odom_samples"] == 901
    assert_reproduces(summary, reference(load_scenario(EXTREME)))


@pytest.mark.realtime
def test_the_real_time_graph_on_rclpy_is_what_ros2_shows(ros_env: dict[str, str], tmp_path: Path) -> None:
    nodes = list(GRAPHS["full"])
    queries = {"observer": ["use_sim_time", "scenario", "simulation.planner", "vehicle.mu"],
               "vehicle_simulator": ["use_sim_time", "scenario", "seed", "rate", "vehicle_bus", "wait_for"],
               "motion_controller": ["use_sim_time", "simulation.planner"]}
    probe = subprocess.Popen(
        [ros_env["MOOSE_ROS_PYTHON"], "-c", PROBE, json.dumps([*nodes, "moose_monitor"]), json.dumps(list(TOPICS)),
         json.dumps(queries), "120"], env=ros_env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        start_new_session=True)
    try:
        bag = tmp_path / "bag"
        result = run([ros_env["MOOSE_ROS_PYTHON"], "-m", "moose.cli", "launch", "--runtime", "rclpy", "--scenario",
                      SCENARIO, "--json", str(tmp_path / "summary.json"), "--bag", str(bag)],
                     ros_env, LIMIT)
        assert result.returncode in (0, 1, 4), result.stderr[-3000:]  # a verdict, perhaps degraded under load
        try:
            seen, probe_err = probe.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            pytest.fail("the rclpy probe did not finish")
    finally:
        if probe.poll() is None:
            os.killpg(probe.pid, signal.SIGKILL)
            probe.wait()
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["runtime"] == {**{n: "rclpy" for n in nodes}, "moose_monitor": "rclpy"}
    check_ran(summary, result.stderr)
    assert "starting without" not in result.stdout  # every node announced itself on /diagnostics in time
    # every node confined on Fast DDS: each checked that its participant's UDP sockets are all on 127.0.0.1
    for name in nodes:
        started = [line for line in (result.stdout + result.stderr).splitlines()
                   if f"[{name}]" in line and f"{name} started (DDS discovery" in line]
        assert started and "Fast DDS bound to loopback (fastdds_loopback.xml); " in started[0], (name, started)
        assert started[0].rstrip().endswith("UDP sockets, all on 127.0.0.1)"), started[0]

    # the summary and the bag, both from the rclpy monitor, agree; the bag read with rosbags alone
    odom = read_odometry(bag)
    assert len(odom) == summary["odom_samples"]
    assert max(abs(y - odom[0][1]) for _t, y in odom) == pytest.approx(summary["max_lateral_offset_m"], abs=1e-6)

    # what a ROS 2 user sees
    assert probe.returncode == 0, probe_err[-3000:]
    report = json.loads(seen.strip().splitlines()[-1])
    assert {(n, "/") for n in [*nodes, "moose_monitor"]} <= {tuple(x) for x in report["nodes"]}
    store = typestore()
    for name, topic in TOPICS.items():
        assert report["topics"].get(name) == [topic.type], name
        pubs, subs = report["graph"][name]["publishers"], report["graph"][name]["subscriptions"]
        # every publisher is a node of the contract, with the contract's QoS and the type's RIHS01 hash
        assert sorted(p[0] for p in pubs) == sorted(n for n in topic.publishers if n in nodes), name
        for _node_name, namespace, kind, type_hash, reliability, durability in pubs:
            assert (namespace, kind, type_hash) == ("/", topic.type, store.hash_rihs01(topic.type)), name
            assert reliability == ("RELIABLE" if topic.qos.reliable else "BEST_EFFORT"), name
            assert durability == ("TRANSIENT_LOCAL" if topic.qos.transient_local else "VOLATILE"), name
        # subscribers: the contract's nodes, the monitor's recorder (every topic), the probe (odom, imu)
        tools = {"moose_monitor"} | ({"ros2_user_probe"} if name in ("/vehicle/odom", "/vehicle/imu") else set())
        assert {s[0] for s in subs} == {n for n in topic.subscribers if n in nodes} | tools, name
        want = topic.subscription_qos
        for node_name, _ns, _kind, _hash, reliability, durability in subs:
            if node_name in topic.subscribers:
                assert reliability == ("RELIABLE" if want.reliable else "BEST_EFFORT"), (name, node_name)
                assert durability == ("TRANSIENT_LOCAL" if want.transient_local else "VOLATILE"), (name, node_name)

    # parameters through rcl_interfaces: what the launcher gave each node
    given = node_overrides("full", "combined", {"scenario": SCENARIO, "vehicle.mu": load_scenario(SCENARIO).mu},
                           rate=1.0)
    params = report["parameters"]
    assert params["observer"]["values"] == {"use_sim_time": True, "scenario": SCENARIO,
                                            "simulation.planner": "combined",
                                            "vehicle.mu": given["observer"]["vehicle.mu"]}
    assert params["vehicle_simulator"]["values"] == {
        "use_sim_time": False, "scenario": SCENARIO, "seed": 0, "rate": 1.0, "vehicle_bus": "topics",
        "wait_for": given["vehicle_simulator"]["wait_for"]}
    assert params["motion_controller"]["values"] == {"use_sim_time": True, "simulation.planner": "combined"}
    assert {"use_sim_time", "scenario", "vehicle.mu", "simulation.planner"} <= set(params["observer"]["names"])

    # samples as a ROS 2 user receives them: simulated time, ROS frames
    for name, frames in (("/vehicle/odom", (FRAME_ODOM, FRAME_TRUTH)), ("/vehicle/imu", (FRAME_IMU, ""))):
        rows = report["samples"][name]
        assert len(rows) >= 100, name
        assert {(r[1], r[2]) for r in rows} == {frames}, name
        stamps = [r[0] for r in rows]
        assert stamps == sorted(stamps) and 0.0 <= stamps[0] and stamps[-1] <= 9.0 + 1e-9, name


def test_mixed_graph_simulator_and_observer_on_rclpy_the_rest_on_cyclone(
        ros_env: dict[str, str], dds_env: dict[str, str], tmp_path: Path) -> None:
    runtimes = {"vehicle_simulator": "rclpy", "observer": "rclpy", "obstacle_detector": "dds", "mpc_planner": "dds",
                "msf_planner": "dds", "weight_fbl": "dds", "motion_controller": "dds"}
    env = {**dds_env, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}  # the launcher: .venv's interpreter, no rclpy
    env.pop("MOOSE_RUNTIME")
    result = run([sys.executable, "-c", MIXED, EXTREME, json.dumps(runtimes), str(tmp_path / "bag")], env, LIMIT)
    (tmp_path / "launch.log").write_text(result.stdout + result.stderr)  # kept by pytest if the test fails
    assert result.returncode == 0, (result.stdout + result.stderr)[-3000:]  # the summary says why
    log, summary = result.stdout.rsplit("\n", 2)[0], json.loads(result.stdout.strip().splitlines()[-1])
    assert summary["runtime"] == {**runtimes, "moose_monitor": "dds"}
    odom = read_odometry(tmp_path / "bag")
    missing = sorted({round(0.01 * k, 2) for k in range(901)} - {round(t, 2) for t, _y in odom})  # from the bag
    assert not summary["degraded"] and summary["odom_samples"] == 901, (summary["incidents"], missing)
    assert_reproduces(summary, reference(load_scenario(EXTREME)))
    # the Cyclone nodes' start-up diagnostics reached the rclpy simulator, which then started simulated time
    assert "starting without" not in log
    for name in runtimes:
        assert f"{name} started" in log
    assert len(odom) == summary["odom_samples"], missing
