"""The node graph as separate processes on Cyclone DDS (loopback, own domain, bounded in time).

What the graph computes is checked in lockstep (``moose launch --lockstep``), against ``moose simulate`` with the
same timing (tests/lockstep_reference.py); how fast it runs is the benchmarks' business (bench/bench_graph.py,
bench/bench_realtime.py).  The tests marked ``realtime`` assert only what holds under load."""
import io
import subprocess
import sys
import textwrap
import time
from dataclasses import dataclass, field
from pathlib import Path

import cyclonedds.idl.types as t
import pytest
from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from isolation import claim_udp_port
from lockstep_reference import assert_reproduces, reference
from moose.params import ParamError
from moose.scenario import load_scenario
from moose_ros.launch import launch
from moose_ros.runtime import DdsNode
from node_output import read_until_started

pytestmark = [pytest.mark.graph, pytest.mark.slow]


ROOT = Path(__file__).resolve().parents[1]


# -- an independent, hand-written nav_msgs/Odometry as any plain Cyclone DDS program would declare it
@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: t.int32 = 0
    nanosec: t.uint32 = 0


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time = field(default_factory=Time)
    frame_id: str = ""


@dataclass
class Point(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: t.float64 = 0.0
    y: t.float64 = 0.0
    z: t.float64 = 0.0


@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: t.float64 = 0.0
    y: t.float64 = 0.0
    z: t.float64 = 0.0
    w: t.float64 = 1.0


@dataclass
class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Point = field(default_factory=Point)
    orientation: Quaternion = field(default_factory=Quaternion)


@dataclass
class PoseWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovariance_"):
    pose: Pose = field(default_factory=Pose)
    covariance: t.array[t.float64, 36] = field(default_factory=lambda: [0.0] * 36)


@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: t.float64 = 0.0
    y: t.float64 = 0.0
    z: t.float64 = 0.0


@dataclass
class Twist(IdlStruct, typename="geometry_msgs::msg::dds_::Twist_"):
    linear: Vector3 = field(default_factory=Vector3)
    angular: Vector3 = field(default_factory=Vector3)


@dataclass
class TwistWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::TwistWithCovariance_"):
    twist: Twist = field(default_factory=Twist)
    covariance: t.array[t.float64, 36] = field(default_factory=lambda: [0.0] * 36)


@dataclass
class Odometry(IdlStruct, typename="nav_msgs::msg::dds_::Odometry_"):
    header: Header = field(default_factory=Header)
    child_frame_id: str = ""
    pose: PoseWithCovariance = field(default_factory=PoseWithCovariance)
    twist: TwistWithCovariance = field(default_factory=TwistWithCovariance)


PUBLISHER = textwrap.dedent("""
    import math, sys, time
    from moose_ros.runtime import create_node, QOS_DEFAULT
    from moose_ros import convert as cv
    import numpy as np
    node = create_node("odom_source")
    pub = node.publisher("nav_msgs/msg/Odometry", "/vehicle/odom", QOS_DEFAULT)
    time.sleep(1.0)  # discovery
    for k in range(100):
        pub(cv.odometry_to_msg(node, 0.01 * k, np.array([0.1 * k, 2.0, 0.3, 7.0, 0.1, 0.05])))
        time.sleep(0.01)
    time.sleep(0.5)
""")


def test_plain_cyclone_reader_receives_odometry_from_another_process() -> None:
    participant = DomainParticipant(int(__import__("os").environ["ROS_DOMAIN_ID"]))
    qos = Qos(Policy.Reliability.Reliable(duration(milliseconds=100)), Policy.History.KeepLast(200))
    reader = DataReader(participant, Topic(participant, "rt/vehicle/odom", Odometry), qos=qos)
    proc = subprocess.Popen([sys.executable, "-c", PUBLISHER])
    samples = []
    deadline = time.monotonic() + 20.0
    try:
        while time.monotonic() < deadline and proc.poll() is None:
            samples.extend(s for s in reader.take(N=100) if isinstance(s, Odometry))
            time.sleep(0.02)
        samples.extend(s for s in reader.take(N=100) if isinstance(s, Odometry))
    finally:
        proc.kill()
        proc.wait()
    assert len(samples) >= 90  # reliable QoS on loopback: (nearly) all 100 arrive
    last = samples[-1]
    assert last.header.frame_id == "odom" and last.child_frame_id == "base_link_truth"  # ground truth (REP-105 frames)
    assert last.pose.pose.position.y == 2.0 and last.twist.twist.linear.x == 7.0
    assert last.pose.pose.orientation.z == pytest.approx(0.14943813)  # sin(0.15)
    assert [s.pose.pose.position.x for s in samples] == sorted(s.pose.pose.position.x for s in samples)


def test_full_graph_reproduces_the_lockstep_outcome() -> None:
    """The extreme case (7 m/s, τ = 1.4 s, ν = 0.95; 0.02 m of clearance under the car's timing): the graph in
    lockstep computes what the loop computes, whatever the machine's load."""
    scenario = load_scenario("paper_v7_tau1.4")
    out = io.StringIO()
    summary = launch(scenario, {"scenario": "paper_v7_tau1.4"}, out=out, lockstep=True)
    log = out.getvalue()
    for node in ("observer", "obstacle_detector", "mpc_planner", "msf_planner", "weight_fbl", "motion_controller",
                 "vehicle_simulator"):
        assert f"[{node}]" in log and f"{node} started" in log
    assert summary["node_exits"] == {name: 0 for name in summary["node_exits"]}  # SIGTERM at the end: status 0
    assert not summary["degraded"] and summary["exit_status"] == 0, summary["incidents"]
    assert summary["complete"] and summary["odom_samples"] == 901  # every tick of the 9 s run, none twice
    assert_reproduces(summary, reference(scenario))


def test_full_graph_with_delay_compensation_reproduces_the_loop_with_it() -> None:
    """``timing.compensate``: the planners predict through the blends they hear on /planning/blend, weight_fbl's
    planning step through its own, the motion controller's EPS loop through its commands — as the loop does."""
    scenario = load_scenario("paper_v7_tau1.4")
    settings = {"timing.compensate": True}
    summary = launch(scenario, {"scenario": "paper_v7_tau1.4", **settings}, out=io.StringIO(), lockstep=True)
    assert summary["timing"]["compensate"] is True and summary["odom_samples"] == 901
    assert_reproduces(summary, reference(scenario, settings=settings))


def test_bad_input_gives_clear_errors(tmp_path: Path) -> None:
    moose = [sys.executable, "-m", "moose.cli"]
    unknown = subprocess.run(moose + ["node", "autopilot"], capture_output=True, text=True, timeout=60)
    assert unknown.returncode == 2 and "node 'autopilot' is unknown" in unknown.stderr
    missing = subprocess.run(moose + ["node", "observer", "--params", str(tmp_path / "no.yaml")],
                             capture_output=True, text=True, timeout=60)
    assert missing.returncode == 2 and "cannot be read: No such file or directory" in missing.stderr
    bad = tmp_path / "bad.yaml"
    bad.write_text("/**:\n  ros__parameters:\n    vehicle: {m: heavy}\n")
    wrong = subprocess.run(moose + ["node", "observer", "--params", str(bad)], capture_output=True, text=True,
                           timeout=60)
    assert wrong.returncode == 2 and "vehicle.m = 'heavy'" in wrong.stderr
    node = DdsNode("typo_check")
    publish = node.publisher("nav_msgs/msg/Odometry", "/vehicle/odom")
    with pytest.raises(TypeError, match="carries 'nav_msgs/msg/Odometry'"):
        publish(node.make("sensor_msgs/msg/Imu"))
    with pytest.raises(TypeError, match="already used with type"):
        node.publisher("sensor_msgs/msg/Imu", "/vehicle/odom")
    with pytest.raises(ParamError, match="no such file"):
        from moose_ros.runtime import create_node
        create_node("x", str(tmp_path / "none.yaml"))


def test_graph_through_the_can_bridge_and_ecu_emulator_reproduces_the_loop(tmp_path: Path) -> None:
    """graph ↔ can_bridge ↔ udp_multicast (loopback, hop limit 0) ↔ vehicle-ECU emulator, in lockstep, on the extreme
    case: the bus is the car's hop (one tick each way, the `car` timing's sensor and command delays), and every
    value crosses it at the DBC's resolution, the one difference from the loop."""
    import os

    scenario = load_scenario("paper_v7_tau1.4")
    log = tmp_path / "bridge.log"
    out = io.StringIO()
    pid = os.getpid()
    summary = launch(scenario, {"scenario": "paper_v7_tau1.4", "can_log": str(log), "can_interface": "udp_multicast",
                                "can_channel": f"239.74.{pid % 250}.{1 + pid % 199}", "can_port": claim_udp_port()},
                     graph="can", out=out, lockstep=True)
    assert "[can_bridge]" in out.getvalue()
    assert summary["node_exits"] == {name: 0 for name in summary["node_exits"]}
    assert not summary["degraded"] and summary["odom_samples"] == 901, summary["incidents"]
    assert_reproduces(summary, reference(scenario))
    assert summary["diagnostics"]["can_bridge"]["level"] == 0
    # the bridge's traffic in candump format, decodable with the DBC
    import can

    from moose.canbus.codec import Codec

    frames = list(can.LogReader(str(log)))
    names = {Codec().db.get_message_by_frame_id(f.arbitration_id).name for f in frames}
    assert {"CMD_STEER", "CMD_TORQUE", "IMU", "WHEEL_SPEEDS", "EPS_STATUS", "GPS_POSITION", "BRIDGE_HEARTBEAT"} <= names


def test_moose_launch_reports_a_collision_that_cannot_be_avoided(tmp_path: Path) -> None:
    """7 m/s, the obstacle ±4 m wide 0.5 s ahead: ½ μ g τ² = 0.98 m of lateral reach (tests/test_metrics.py).
    The whole graph through the command line, as a user runs it."""
    import json

    from moose.verdict import EXIT_FAILED

    out = tmp_path / "summary.json"
    proc = subprocess.run([sys.executable, "-m", "moose.cli", "launch", "--speed", "7", "--tau", "0.5",
                           "--obstacle-half-width", "4", "--duration", "2", "--json", str(out), "--no-bag",
                           "--lockstep"],
                          capture_output=True, text=True, timeout=240)
    assert proc.returncode == EXIT_FAILED == 1, proc.stderr[-2000:]
    assert "Traceback" not in proc.stderr and "COLLISION" in proc.stdout
    summary = json.loads(out.read_text())
    assert summary["odom_samples"] > 250 and summary["complete"]  # 3 s at 100 Hz arrived
    assert summary["outcome"] == "collision" and summary["collided"] is True
    # through the middle of a 2 m long zone: at most 1 m from its ends, at least 0.5 m deep (3 m from its sides)
    assert -1.0 - 1e-9 <= summary["min_clearance_m"] < -0.5


def test_a_real_time_simulator_starts_its_clock_only_once_the_monitor_reads_it() -> None:
    """Real time: the simulator starts simulated time only once its publishers reach every reader it expects, the
    launcher's monitor among them (``monitored``).  An rclpy monitor on a loaded machine matched the odometry
    0.45 s into the run and judged it incomplete; here the reader joins 2 s after the simulator is up, and its first
    odometry sample is still the run's first."""
    from moose_ros.graph import ODOM, TOPICS
    from moose_ros.lockstep import MONITORED
    from moose_ros.process import spawn, stop
    from moose_ros.runtime import create_node

    sim = spawn([sys.executable, "-m", "moose_ros.nodes", "vehicle_simulator", "--param", "scenario=paper_v5_tau3",
                 "--param", "monitored=true", "--param", "rate=2"],
                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    node = None
    try:
        read_until_started(sim, "vehicle_simulator")
        time.sleep(2.0)  # the monitor joins late (at rate 2 the run would be 4 simulated s on without the wait)
        node = create_node("moose_monitor", overrides={"use_sim_time": False})
        stamps: list[float] = []
        for name in MONITORED:  # what the launcher's monitor reads
            topic = TOPICS[name]
            node.subscription(topic.type, name, (lambda m: stamps.append(m.header.stamp.sec + 1e-9 *
                                                                         m.header.stamp.nanosec))
                              if topic is ODOM else (lambda m: None), topic.tool_qos)
        deadline = time.monotonic() + 60.0
        while not stamps and time.monotonic() < deadline:
            node.spin_once(0.05)
    finally:
        if node is not None:
            node.shutdown()
        stop([sim], grace=10.0)
    assert stamps and stamps[0] <= 0.011, stamps[:3]
