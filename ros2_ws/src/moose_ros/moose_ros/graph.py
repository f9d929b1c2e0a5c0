"""The graph contract: every topic, every frame, every node, the launch graphs and the defaults they share.

One definition of each fact of the node graph (paper Fig. 3). Nodes publish and subscribe through
:meth:`Topic.publisher` and :meth:`Topic.subscription`; the launcher, the bag recorder and player,
the ROS 2 launch files, ``setup.py``'s entry points and the topic table of docs/graph.md are taken
from here or checked against it by ``tests/test_graph_contract.py``.

This module is light on purpose (no middleware, no planner): every node, the launcher and the
command line import it.
"""
from __future__ import annotations

import dataclasses
from typing import Any, Callable, Optional

from .runtime.base import Handle, NodeBase, Publisher
from .runtime.names import CLOCK_TOPIC, CLOCK_TYPE
from .runtime.qos import (
    QOS_CLOCK,
    QOS_CLOCK_READER,
    QOS_DEFAULT,
    QOS_LATCHED,
    QOS_LATCHED_READER,
    QOS_SENSOR,
    Qos,
)

STAMP_TOLERANCE = 0.5
"""How far (s) a received message's stamp may lie ahead of the receiver's clock before it is dropped as invalid
(:func:`moose_ros.convert.checked_time`).  Within one graph every stamp comes from one clock (simulated time, or
the host's wall clock on the car) and a subscriber's clock lags by at most its queue: a keep-last-10 backlog at
100 Hz is 0.1 s.  A sample from much further ahead would make the observer refuse every real sample after it as
out of order, so it is refused instead.  Graphs across hosts need their clocks synchronised far better (PTP,
chrony)."""


@dataclasses.dataclass(frozen=True)
class Node:
    """A node of the graph: one ECU function (paper Fig. 3)."""

    name: str
    """Node and executable name (``moose node NAME``, ``ros2 run moose_ros NAME``)."""
    group: str
    """ECU group (one service of docker/compose.yaml, one ``group:=`` of the ROS 2 launch file)."""
    implementation: str
    """``module:Class`` under ``moose_ros.nodes`` (imported only when the node starts, so a node loads
    only what its job needs)."""
    job: str
    """What it does, in one line."""
    redundant: bool = False
    """One of two nodes that can do the job (the planners): its failure degrades the graph (``weight_fbl``
    applies the other planner's plan) instead of stopping the car."""


NODES: dict[str, Node] = {n.name: n for n in (
    Node("vehicle_simulator", "vehicle", "simulator:VehicleSimulator",
         "plant, sensors and the scenario's obstacle; owns simulated time (/clock)"),
    Node("observer", "perception", "observer:Observer", "state observer: vehicle sensors → state estimate"),
    Node("obstacle_detector", "perception", "detector:Detector", "state + danger zones → threat (τ, w, ν)"),
    Node("mpc_planner", "planning", "planner:MpcPlannerNode", "MPC planner at the planning rate and on a new obstacle",
         redundant=True),
    Node("msf_planner", "planning", "planner:MsfPlannerNode",
         "MSF planner (or a baseline, aeb or max_steer) at the planning rate and on a new obstacle", redundant=True),
    Node("weight_fbl", "planning", "weight_fbl:WeightFbl", "weight function and FBL: blend → references"),
    Node("motion_controller", "control", "motion:Motion", "PI speed control, TDL, feedback EPS → actuator command"),
    Node("can_bridge", "bridge", "can_bridge:CanBridge", "actuator command ↔ guarded CAN frames ↔ sensor topics"),
)}
"""Every node of the graph, in start order."""

GROUPS: dict[str, tuple[str, ...]] = {
    group: tuple(n.name for n in NODES.values() if n.group == group) for group in dict.fromkeys(
        n.group for n in NODES.values())
}
"""Nodes by ECU group: perception, planning (the MicroLabBox), control (the AutoBox), vehicle, bridge."""

GRAPHS: dict[str, tuple[str, ...]] = {
    "full": ("vehicle_simulator", "observer", "obstacle_detector", "mpc_planner", "msf_planner", "weight_fbl",
             "motion_controller"),
    "car": ("observer", "obstacle_detector", "mpc_planner", "msf_planner", "weight_fbl", "motion_controller",
            "can_bridge"),
    "can": ("vehicle_simulator", "observer", "obstacle_detector", "mpc_planner", "msf_planner", "weight_fbl",
            "motion_controller", "can_bridge"),
}
"""The graphs ``moose launch`` starts. ``full``: with the vehicle simulator on topics; ``car``: the graph that
runs on the vehicle (sensors and actuators through the CAN bridge); ``can``: ``car`` plus the simulator as
the vehicle-side ECU emulator behind the DBC, over ``udp_multicast`` here."""

SENSOR_SOURCES = ("vehicle_simulator", "can_bridge")
"""Who publishes the vehicle's sensor topics: the simulator on topics, or the CAN bridge from the bus."""

# -- frames (REP-105) --------------------------------------------------------------------------------
FRAME_ODOM = "odom"
"""The world-fixed frame of the run (x along the initial heading, y left)."""
FRAME_BASE = "base_link"
"""The vehicle at its CoG as the stack believes it: ``odom → base_link`` is the observer's estimate (on the
car as in simulation; the state estimator owns this transform, REP-105)."""
FRAME_TRUTH = "base_link_truth"
"""The vehicle at its CoG in truth: ``odom → base_link_truth`` is the simulator's ground truth, a second child
of ``odom`` beside ``base_link`` so that the two never fight over one transform."""
FRAME_IMU = "imu"
FRAME_GPS = "gps"
SENSOR_MOUNTS: dict[str, tuple[float, float, float]] = {FRAME_IMU: (0.0, 0.0, 0.0), FRAME_GPS: (0.0, 0.0, 0.0)}
"""Each sensor's frame: its position in ``base_link`` (m; no rotation). The sensor model measures at the CoG
(the paper gives no mounting positions), so both are at the origin; /tf_static carries them."""


@dataclasses.dataclass(frozen=True)
class Topic:
    """A topic of the graph: name, message type, QoS, designed rate, who publishes and who subscribes."""

    name: str
    type: str
    """``pkg/msg/Type``."""
    qos: Qos
    """What its publishers offer."""
    rate: str
    """Designed rate, as documented (``"100 Hz"``, ``"5 Hz + on a new obstacle"``)."""
    rate_hz: Optional[float]
    """Designed periodic rate (Hz); ``None`` for a topic published on events only."""
    publishers: tuple[str, ...]
    subscribers: tuple[str, ...]
    """Nodes of the graph (tools such as the launcher's monitor and the recorder subscribe to every topic)."""
    content: str = ""
    """What it carries beyond the type name (frames, units), for the topic table."""
    reader_qos: Optional[Qos] = None
    """What its subscribers request, when that differs from :attr:`qos`."""
    tolerance: int = 10
    """Designed periods a subscriber waits for the next sample before the input is stale (:attr:`deadline`).
    Ten by default: 0.1 s at 100 Hz, twice the worst lag measured under CPU load (56 ms, eight busy loops on
    two cores), so that load is counted as deadline misses instead of stopping the car, while a dead
    publisher is noticed within 0.7 m at the paper's speeds.  Five for the actuator commands: the vehicle
    ECU's 50 ms timeout, a fact of the car."""

    @property
    def deadline(self) -> Optional[float]:
        """How long after its last sample (s, on the subscriber's clock) this input is stale: ``tolerance``
        designed periods; ``None`` for a topic published on events only.  Every node supervises its inputs
        with these (``moose_ros.nodes.base.InputWatch``), so the deadlines live here, next to the rates."""
        return None if self.rate_hz is None else self.tolerance / self.rate_hz

    @property
    def subscription_qos(self) -> Qos:
        return self.reader_qos or self.qos

    def publisher(self, rt: NodeBase) -> Publisher:
        """A publisher of this topic on runtime node ``rt``."""
        return rt.publisher(self.type, self.name, self.qos)

    def subscription(self, rt: NodeBase, callback: Callable[[Any], None]) -> Handle:
        """A subscription to this topic on runtime node ``rt``, with the subscribers' QoS."""
        return rt.subscription(self.type, self.name, callback, self.subscription_qos)

    @property
    def tool_qos(self) -> Qos:
        """What tools that must not miss a sample request (the launcher's monitor, the bag recorder): the
        publishers' reliability and durability, as rosbag2 adapts its request to the offers, and a keep-last
        depth of at least 100 (a latched topic keeps one sample per writer)."""
        base = self.subscription_qos if self.qos.transient_local else self.qos
        return Qos(reliable=self.qos.reliable, depth=max(base.depth, 100), transient_local=self.qos.transient_local)

    def tool_subscription(self, rt: NodeBase, callback: Callable[[Any], None]) -> Handle:
        """A subscription of a tool (monitor, recorder) with :attr:`tool_qos`."""
        return rt.subscription(self.type, self.name, callback, self.tool_qos)


QOS_TF = Qos(reliable=True, depth=100)
"""tf2's TransformBroadcaster and TransformListener: reliable, volatile, keep last 100."""
QOS_SENSOR_PUBLISHER = QOS_DEFAULT
"""REP-2003: sensor drivers publish with the system default QoS (reliable), so that every subscriber matches."""

_ALL = tuple(NODES)
CLOCK = Topic(CLOCK_TOPIC, CLOCK_TYPE, QOS_CLOCK, "100 Hz", 100.0, ("vehicle_simulator",),
              tuple(n for n in _ALL if n != "vehicle_simulator"), "simulated time (use_sim_time)",
              reader_qos=QOS_CLOCK_READER)
ODOM = Topic("/vehicle/odom", "nav_msgs/msg/Odometry", QOS_SENSOR_PUBLISHER, "100 Hz", 100.0, ("vehicle_simulator",),
             (), "odom → base_link_truth, ground truth", reader_qos=QOS_SENSOR)
IMU = Topic("/vehicle/imu", "sensor_msgs/msg/Imu", QOS_SENSOR_PUBLISHER, "100 Hz", 100.0, SENSOR_SOURCES, ("observer",),
            "frame imu; a_x, a_y, γ", reader_qos=QOS_SENSOR)
GPS = Topic("/vehicle/gps", "nav_msgs/msg/Odometry", QOS_SENSOR_PUBLISHER, "1 Hz", 1.0, SENSOR_SOURCES, ("observer",),
            "odom → gps fix, stamped at measurement, sent 0.2 s later; read reliably (one fix a second)", tolerance=3)
WHEEL_SPEEDS = Topic("/vehicle/wheel_speeds", "moose_msgs/msg/WheelSpeeds", QOS_SENSOR_PUBLISHER, "100 Hz", 100.0,
                     SENSOR_SOURCES, ("observer", "motion_controller"), "rear wheel speeds", reader_qos=QOS_SENSOR)
STEERING = Topic("/vehicle/steering", "moose_msgs/msg/SteeringReport", QOS_SENSOR_PUBLISHER, "100 Hz", 100.0,
                 SENSOR_SOURCES, ("observer", "motion_controller"), "EPS steering angle", reader_qos=QOS_SENSOR)
OBSTACLES = Topic("/perception/obstacles", "moose_msgs/msg/ObstacleArray", QOS_LATCHED, "on appearance", None,
                  ("vehicle_simulator",), ("obstacle_detector",), "danger zones seen by the perception sensor")
STATE = Topic("/perception/state", "moose_msgs/msg/StateEstimate", QOS_DEFAULT, "100 Hz", 100.0, ("observer",),
              ("obstacle_detector", "mpc_planner", "msf_planner", "weight_fbl", "motion_controller"),
              "x, y, θ, v_x, v_y, γ, δ")
THREAT = Topic("/perception/threat", "moose_msgs/msg/Threat", QOS_DEFAULT, "100 Hz", 100.0, ("obstacle_detector",),
               ("mpc_planner", "msf_planner", "weight_fbl"), "τ, w, ν, side")
PLAN_MPC = Topic("/planning/mpc", "moose_msgs/msg/PlannerOutput", QOS_DEFAULT, "5 Hz + on a new obstacle", 5.0,
                 ("mpc_planner",), ("weight_fbl",), "planned accelerations, status", tolerance=2)
PLAN_MSF = Topic("/planning/msf", "moose_msgs/msg/PlannerOutput", QOS_DEFAULT, "5 Hz + on a new obstacle", 5.0,
                 ("msf_planner",), ("weight_fbl",), "planned accelerations, status", tolerance=2)
BLEND = Topic("/planning/blend", "moose_msgs/msg/Blend", QOS_DEFAULT, "5 Hz", 5.0, ("weight_fbl",),
              ("mpc_planner", "msf_planner"), "w_MPC, the blended plan (the MPC's next initial guess; with "
              "timing.compensate the accelerations in flight), δ*, δ_MPC", tolerance=2)
REFERENCE = Topic("/control/reference", "moose_msgs/msg/Reference", QOS_DEFAULT,
                  "100 Hz (δ* re-evaluated per estimate)", 100.0, ("weight_fbl",), ("motion_controller",), "δ*, v_x*")
ACTUATOR_COMMAND = Topic("/control/actuator_command", "moose_msgs/msg/ActuatorCommand", QOS_DEFAULT,
                         "100 Hz (per estimate)", 100.0, ("motion_controller",), ("vehicle_simulator", "can_bridge"),
                         "δ*, δ̇_cmd, T_rl, T_rr", tolerance=5)
DIAGNOSTICS = Topic("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", QOS_LATCHED, "1 Hz + on start and change",
                    1.0, _ALL, ("vehicle_simulator", "motion_controller"),
                    "each node's status; the simulator starts the clock when all reported; the motion controller "
                    "stops the car when a node it needs reports an error or falls silent",
                    reader_qos=QOS_LATCHED_READER, tolerance=3)

TF = Topic("/tf", "tf2_msgs/msg/TFMessage", QOS_TF, "100 Hz per publisher", 100.0, ("vehicle_simulator", "observer"),
           (), "odom → base_link (observer, estimate), odom → base_link_truth (simulator, ground truth)")
TF_STATIC = Topic("/tf_static", "tf2_msgs/msg/TFMessage", QOS_LATCHED, "once at start", None, SENSOR_SOURCES, (),
                  "base_link → imu, gps (sensor mounts)", reader_qos=QOS_LATCHED_READER)
MARKERS = Topic("/planning/markers", "visualization_msgs/msg/MarkerArray", QOS_DEFAULT, "5 Hz (per blend)", 5.0,
                ("weight_fbl",), (), "in odom: danger zone, its width w, MPC, MSF and blended predicted paths")

def _defined(value: Optional[float]) -> float:
    assert value is not None
    return value


COMMAND_TIMEOUT = _defined(ACTUATOR_COMMAND.deadline)
"""Actuator commands older than this (s) are stale: five 10 ms command cycles, the vehicle ECU's timeout.
The one value of the command guard of the CAN bridge, the vehicle-ECU emulator and the simulator's
topic input (which stands in for the same ECUs)."""

TOPICS: dict[str, Topic] = {t.name: t for t in (
    CLOCK, ODOM, IMU, GPS, WHEEL_SPEEDS, STEERING, OBSTACLES, STATE, THREAT, PLAN_MPC, PLAN_MSF, BLEND, REFERENCE,
    ACTUATOR_COMMAND, DIAGNOSTICS, TF, TF_STATIC, MARKERS,
)}
"""Every topic of the graph by name."""

PLANS: dict[str, Topic] = {"mpc": PLAN_MPC, "msf": PLAN_MSF}
"""The output topic of each planner."""

# -- supervision (moose_ros.nodes.base) -------------------------------------------------------------
SUPERVISION_PERIOD = 1.0 / _defined(ACTUATOR_COMMAND.rate_hz)
"""How often every node checks its inputs' deadlines and its own executor (s, on its clock): the command cycle."""
STARTUP_GRACE = 1.0
"""An input never received is stale this long after the node's clock started (s): the graph's first plan and
reference arrive within 0.3 s; the obstacle appears after the scenario's lead time (1 s)."""
CYCLE_DEADLINE = COMMAND_TIMEOUT
"""A node whose executor runs no cycle for longer than this (s) missed a deadline: its 100 Hz inputs went
stale meanwhile (the vehicle ECU's command timeout)."""
STALL_TIME = 0.25
"""A node whose executor runs no cycle for longer than this (s) stalled (SIGSTOP, a hung callback, a starved CPU):
five times the tightest deadline, and longer than any planning solve that still meets its 0.2 s slot."""
CONTROL_LAG_MAX = 2.0 / _defined(ACTUATOR_COMMAND.rate_hz)
"""The motion controller missed a deadline when it commands on an estimate older than this (s, on its clock):
two command cycles; the lockstep loop commands on the estimate of the same cycle."""


def essential_upstream(node: str) -> tuple[str, ...]:
    """The nodes whose output ``node`` needs and cannot do without: the publishers of its inputs and, walking
    upstream, of theirs — but not through a :attr:`Node.redundant` node (a planner), whose failure the graph
    absorbs (``weight_fbl`` applies the other plan).  ``/clock`` and ``/diagnostics`` are not data inputs.
    The motion controller stops the car when one of these reports an error or falls silent on /diagnostics."""
    found: list[str] = []
    todo = [node]
    while todo:
        current = todo.pop()
        for topic in subscribes(current):
            if topic is CLOCK or topic is DIAGNOSTICS:
                continue
            for publisher in topic.publishers:
                if publisher == node or publisher in found or NODES[publisher].redundant:
                    continue
                found.append(publisher)
                todo.append(publisher)
    return tuple(n for n in NODES if n in found)


def publishes(node: str) -> list[Topic]:
    """The topics ``node`` publishes."""
    return [t for t in TOPICS.values() if node in t.publishers]


def subscribes(node: str) -> list[Topic]:
    """The topics ``node`` subscribes to (``/clock`` through the runtime, with ``use_sim_time``)."""
    return [t for t in TOPICS.values() if node in t.subscribers]


def qos_text(q: Qos) -> str:
    """``reliable, transient local, keep last 1``: a QoS in words (the topic table, the nodes' docstrings)."""
    parts = ["reliable" if q.reliable else "best effort"] + (["transient local"] if q.transient_local else [])
    return ", ".join(parts + [f"keep last {q.depth}"])


def topic_table() -> str:
    """The Markdown topic table of docs/graph.md, "Node graph"."""
    rows = ["| topic | type | content | publishers → subscribers | rate | deadline | QoS (publishers; subscribers if "
            "other) |", "|---|---|---|---|---|---|---|"]
    for t in TOPICS.values():
        subscribers = ", ".join(t.subscribers) or "tools (monitor, recorder)"
        reader = f"; {qos_text(t.reader_qos)}" if t.reader_qos else ""
        deadline = "—" if t.deadline is None else f"{t.deadline:g} s"
        rows.append(f"| `{t.name}` | {t.type} | {t.content} | {', '.join(t.publishers)} → {subscribers} | {t.rate} "
                    f"| {deadline} | {qos_text(t.qos)}{reader} |")
    return "\n".join(rows)
