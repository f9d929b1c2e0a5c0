"""Every subscriber validates what it receives: bad messages are dropped, counted and reported, never fatal.

The validation lives in one place, the message → record conversion (moose_ros.convert); nodes subscribe
through GraphNode.subscribe.  The unit tests pin what is invalid; the graph tests publish hostile messages
from another participant into running node processes and read the nodes' /diagnostics: the regression
of the review (one ObstacleArray with x_min > x_max made obstacle_detector exit, and the car hit the
obstacle), and every topic every node subscribes to.
"""
from __future__ import annotations

import math
import subprocess
import sys
import time
from types import SimpleNamespace
from typing import Any, Callable

import numpy as np
import pytest

from moose.signals import Obstacle, PlanResult, Reference, StateEstimate, Threat
from moose_ros import convert as cv
from moose_ros.graph import (
    ACTUATOR_COMMAND,
    BLEND,
    DIAGNOSTICS,
    GPS,
    IMU,
    NODES,
    OBSTACLES,
    PLAN_MPC,
    PLAN_MSF,
    REFERENCE,
    STAMP_TOLERANCE,
    STATE,
    STEERING,
    THREAT,
    TOPICS,
    WHEEL_SPEEDS,
    subscribes,
)
from moose_ros.interfaces import make
from moose_ros.runtime import DdsNode

F = SimpleNamespace(make=make)
"""A message factory (what a runtime node offers as ``make``)."""


def valid(topic: str, t: float) -> Any:
    """A valid message of ``topic`` stamped ``t``."""
    e = StateEstimate(t, 1.0, 0.2, 0.01, 7.0, 0.1, 0.02, 0.03)
    zone = Obstacle(9.0, 11.0, -2.0, 2.0)
    plan = PlanResult(np.ones((4, 2)), "converged", 3, 0.002, 1.5, np.zeros((5, 4)))
    from moose.signals import Blend, EpsSample, GpsSample, ImuSample, WheelSpeedSample

    return {
        IMU.name: lambda: cv.imu_to_msg(F, ImuSample(t, 0.1, 0.2, 0.3)),
        GPS.name: lambda: cv.gps_to_msg(F, GpsSample(t, t, 1.0, 2.0, 7.0, 0.0)),
        WHEEL_SPEEDS.name: lambda: cv.wheels_to_msg(F, WheelSpeedSample(t, 20.0, 20.0)),
        STEERING.name: lambda: cv.steering_to_msg(F, EpsSample(t, 0.05)),
        OBSTACLES.name: lambda: cv.obstacles_to_msg(F, t, [zone]),
        STATE.name: lambda: cv.estimate_to_msg(F, e),
        THREAT.name: lambda: cv.threat_to_msg(F, t, Threat(t, zone, 1.4, 2.0, 0.95, 1, 0.0)),
        PLAN_MPC.name: lambda: cv.plan_to_msg(F, t, "mpc", plan, True),
        PLAN_MSF.name: lambda: cv.plan_to_msg(F, t, "msf", plan, True),
        BLEND.name: lambda: cv.blend_to_msg(F, t, Blend(0.4, np.ones((4, 2))), Reference(0.1, 7.0)),
        REFERENCE.name: lambda: cv.reference_to_msg(F, t, Reference(0.1, 7.0)),
        ACTUATOR_COMMAND.name: lambda: cv.actuator_to_msg(F, t, Reference(0.1, 7.0), np.array([0.5, 20.0, 20.0])),
        DIAGNOSTICS.name: lambda: cv.diagnostic_to_msg(F, t, "some_node", 0, "running", {}),
    }[topic]()


def spoil(field: str, value: Any) -> Callable[[Any], None]:
    """Set a dotted field (``a.b[0].c``) of a message."""

    def apply(msg: Any) -> None:
        *path, leaf = field.split(".")
        target = msg
        for part in path:
            name, _, index = part.partition("[")
            target = getattr(target, name)
            if index:
                target = target[int(index[:-1])]
        setattr(target, leaf, value)

    return apply


NAN, INF = math.nan, math.inf
HOSTILE: dict[str, list[Callable[[Any], None]]] = {
    IMU.name: [spoil("linear_acceleration.x", NAN), spoil("angular_velocity.z", INF)],
    GPS.name: [spoil("pose.pose.position.x", NAN), spoil("twist.twist.linear.y", -INF)],
    WHEEL_SPEEDS.name: [spoil("omega_rl", NAN)],
    STEERING.name: [spoil("delta", NAN)],
    OBSTACLES.name: [spoil("obstacles[0].x_min", 12.0), spoil("obstacles[0].y_max", NAN),  # x_min > x_max: the probe
                     spoil("obstacles[0].x_max", INF)],
    STATE.name: [spoil("vx", NAN), spoil("theta", INF)],
    THREAT.name: [spoil("tau", NAN), spoil("side", 0), spoil("obstacle.y_min", 3.0)],
    PLAN_MPC.name: [spoil("status", 200), spoil("accel_x", [0.0, NAN, 0.0, 0.0]), spoil("accel_y", [0.0])],
    PLAN_MSF.name: [spoil("predicted_y", [0.0]), spoil("solve_time", -1.0)],
    BLEND.name: [spoil("weight_mpc", 1.5), spoil("accel_y", [INF] * 4)],
    REFERENCE.name: [spoil("delta_ref", NAN)],
    ACTUATOR_COMMAND.name: [spoil("steering_angle", NAN), spoil("torque_rl", INF)],
    DIAGNOSTICS.name: [spoil("status[0].level", 9), spoil("status[0].name", "")],
}
"""Invalid variants of each subscribed topic's messages (numbers, geometry, enumerations, array lengths)."""
BAD_STAMPS: list[Callable[[Any], None]] = [spoil("header.stamp.sec", -3), spoil("header.stamp.nanosec", 1_500_000_000)]


def test_every_subscribed_topic_has_a_validating_converter_and_hostile_cases() -> None:
    subscribed = {t.name for n in NODES for t in subscribes(n)} - {"/clock"}  # the clock is the runtime's
    assert set(cv.RECORDS) == subscribed == set(HOSTILE)


@pytest.mark.parametrize("topic", sorted(HOSTILE))
def test_valid_messages_convert_and_invalid_ones_are_refused_with_the_field_named(topic: str) -> None:
    convert = cv.RECORDS[topic]
    convert(valid(topic, 5.0), 5.0)  # valid, also at the receiver's own time
    convert(valid(topic, 5.0 + STAMP_TOLERANCE), 5.0)
    convert(valid(topic, 1e9), None)  # the receiver's clock unknown: no look-ahead check
    for case in HOSTILE[topic] + BAD_STAMPS:
        msg = valid(topic, 5.0)
        case(msg)
        with pytest.raises(cv.InvalidMessage, match=r"is invalid"):
            convert(msg, 5.0)
    with pytest.raises(cv.InvalidMessage, match=r"ahead of this node's clock"):
        convert(valid(topic, 5.0 + STAMP_TOLERANCE + 0.01), 5.0)


def test_records_keep_their_values() -> None:
    assert cv.threat_from_msg(valid(THREAT.name, 5.0), 5.0) == Threat(5.0, Obstacle(9.0, 11.0, -2.0, 2.0), 1.4, 2.0,
                                                                       0.95, 1, 0.0)
    assert cv.obstacles_from_msg(valid(OBSTACLES.name, 5.0)) == [Obstacle(9.0, 11.0, -2.0, 2.0)]
    t, with_threat, plan = cv.stamped_plan_from_msg(valid(PLAN_MPC.name, 5.0))
    assert t == 5.0 and with_threat and plan.status == "converged"
    assert plan.accel.shape == (4, 2) and plan.predicted.shape == (5, 4)
    command = cv.actuator_from_msg(valid(ACTUATOR_COMMAND.name, 5.0))
    assert (command.steering_angle, command.steering_rate, command.torque_rl) == (0.1, 0.5, 20.0)
    assert cv.statuses_from_msg(valid(DIAGNOSTICS.name, 5.0)) == [("some_node", 0, "running")]
    inactive = valid(THREAT.name, 5.0)
    inactive.active = False
    assert cv.threat_from_msg(inactive) is None


# -- from outside the process -------------------------------------------------------------------------------------


class Graph:
    """Node processes (``moose node NAME``) and a participant of the test that publishes and reads /diagnostics."""

    def __init__(self, names: list[str], extra: dict[str, list[str]]) -> None:
        self.node = DdsNode("hostile_source")
        self.status: dict[str, tuple[int, str, dict[str, str]]] = {}
        self.warned: set[str] = set()
        """Nodes that reported dropping invalid messages at WARN."""
        self.node.subscription(DIAGNOSTICS.type, DIAGNOSTICS.name, self._on_diag, DIAGNOSTICS.subscription_qos)
        self.threats: list[Any] = []
        THREAT.subscription(self.node, self.threats.append)
        self.pubs = {name: topic.publisher(self.node) for name, topic in TOPICS.items() if name in HOSTILE}
        self.procs = {n: subprocess.Popen([sys.executable, "-m", "moose.cli", "node", n, *extra.get(n, [])],
                                          stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
                      for n in names}

    def _on_diag(self, msg: Any) -> None:
        for s in msg.status:
            level = s.level if isinstance(s.level, int) else s.level[0]
            self.status[s.name] = (level, s.message, {kv.key: kv.value for kv in s.values})
            if level == 1 and "invalid message" in s.message:
                self.warned.add(s.name)

    def spin_until(self, condition: Callable[[], bool], limit: float) -> bool:
        deadline = time.monotonic() + limit
        while not condition() and time.monotonic() < deadline:
            self.node.spin_once(0.05)
            dead = {n: p.returncode for n, p in self.procs.items() if p.poll() is not None}
            assert not dead, f"nodes exited: {dead}; stderr: {self.stderr()}"
        return condition()

    def stderr(self) -> dict[str, str]:
        out = {}
        for name, proc in self.procs.items():
            if proc.poll() is not None and proc.stderr is not None:
                out[name] = proc.stderr.read()[-2000:]
        return out

    def publish(self, topic: str, msg: Any) -> None:
        self.pubs[topic](msg)
        self.node.spin_once(0.02)

    def close(self) -> None:
        for proc in self.procs.values():
            proc.kill()
        for proc in self.procs.values():
            proc.wait(timeout=20)
        self.node.shutdown()


@pytest.mark.graph
@pytest.mark.slow
def test_an_inconsistent_obstacle_is_dropped_and_reported_and_the_detector_keeps_working() -> None:
    """The review's probe: one ObstacleArray with x_min > x_max from any participant made obstacle_detector exit."""
    graph = Graph(["obstacle_detector"], {})
    try:
        assert graph.spin_until(lambda: "obstacle_detector" in graph.status, 60.0), "the detector did not start"
        bad = valid(OBSTACLES.name, time.time())
        bad.obstacles[0].x_min, bad.obstacles[0].x_max = 12.0, 11.0
        graph.publish(OBSTACLES.name, bad)
        for _ in range(30):  # a car approaching at 7 m/s, 3 m before the zone (wall-clock stamps: no sim time)
            graph.publish(STATE.name, cv.estimate_to_msg(F, StateEstimate(time.time(), 6.0, 0.0, 0.0, 7.0, 0, 0, 0)))
        assert graph.spin_until(
            lambda: graph.status["obstacle_detector"][2].get("invalid /perception/obstacles") == "1", 5.0), \
            graph.status
        level, message, values = graph.status["obstacle_detector"]
        assert level == 1 and "dropped 1 invalid message" in message
        assert "ObstacleArray.obstacles[0].x_min = 12.0 is invalid" in values["invalid:/perception/obstacles"]
        assert all(not m.active for m in graph.threats)  # the bad zone was never used
        graph.publish(OBSTACLES.name, valid(OBSTACLES.name, time.time()))  # the real obstacle still counts
        for _ in range(20):
            graph.publish(STATE.name, cv.estimate_to_msg(F, StateEstimate(time.time(), 6.0, 0.0, 0.0, 7.0, 0, 0, 0)))
        assert graph.spin_until(lambda: any(m.active for m in graph.threats), 5.0)
        assert graph.procs["obstacle_detector"].poll() is None
    finally:
        graph.close()


@pytest.mark.graph
@pytest.mark.slow
def test_every_node_drops_counts_and_reports_hostile_input_on_every_topic_it_subscribes_to() -> None:
    names = [n for n in NODES if subscribes(n)]
    extra = {"vehicle_simulator": ["--param", "duration=100"], "can_bridge": ["--param", "can_interface=virtual"]}
    graph = Graph(names, extra)
    try:
        assert graph.spin_until(lambda: set(names) <= set(graph.status), 120.0), \
            f"not up: {set(names) - set(graph.status)}"
        sent: dict[str, int] = {}
        for topic, cases in HOSTILE.items():
            for case in cases + BAD_STAMPS:
                msg = valid(topic, time.time())
                case(msg)
                graph.publish(topic, msg)
                sent[topic] = sent.get(topic, 0) + 1
            future = valid(topic, time.time() + 10.0)  # 10 s ahead of every node's clock (all on wall time here)
            graph.publish(topic, future)
            sent[topic] += 1

        def counted(node: str, topic: str) -> int:
            return int(graph.status.get(node, (0, "", {}))[2].get(f"invalid {topic}", "0"))

        expected = {(n, t.name) for n in names for t in subscribes(n) if t.name in HOSTILE}

        # a best-effort reader (the sensor topics' subscribers) may lose a sample under load: it must count some
        def reported() -> bool:
            return all(counted(n, t) == sent[t] or (not TOPICS[t].subscription_qos.reliable and counted(n, t) > 0)
                       for n, t in expected)

        graph.spin_until(lambda: reported() and graph.warned >= set(names), 10.0)
        missing = {(n, t): (counted(n, t), sent[t]) for n, t in expected if counted(n, t) != sent[t]}
        assert all(not TOPICS[t].subscription_qos.reliable and got > 0 for (n, t), (got, _) in missing.items()), missing
        assert graph.warned == set(names)  # each one said so at WARN
        assert all(graph.procs[n].poll() is None for n in names)  # and none of them exited
    finally:
        graph.close()
