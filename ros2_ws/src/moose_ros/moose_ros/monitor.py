"""The launcher's monitor (:class:`Monitor`): what the graph publishes, collected into a :class:`SimulationResult`.

It reads odometry, steering, plans, blends, threats and diagnostics (:data:`moose_ros.lockstep.MONITORED`, with a
tool's QoS: it must not miss a sample), keeps each node's last status and its arrival (for the launcher's heartbeat
watch), the incidents the statuses report (:class:`moose_ros.incidents.IncidentLog`) and the achieved real-time
factor; :meth:`Monitor.result` is the run as ``moose simulate`` would have returned it.
"""
from __future__ import annotations

import dataclasses
import math
import time
from typing import Any, Callable, Optional

import numpy as np

from moose.planner.step import PlanningRecord
from moose.scenario import Scenario
from moose.schema import Config, PlannerMode
from moose.signals import Blend, Reference
from moose.simulation import SimulationResult

from . import convert as cv
from .graph import BLEND, DIAGNOSTICS, ODOM, PLAN_MPC, STEERING, THREAT, TOPICS
from .incidents import IncidentLog
from .lockstep import MONITOR_ACK_EVERY, MONITORED, tick_of
from .runtime.base import NodeBase


@dataclasses.dataclass
class Monitor:
    """Collects what the graph publishes into a :class:`SimulationResult`."""

    scenario: Scenario
    config: Config
    odom: list = dataclasses.field(default_factory=list)
    delta: float = 0.0
    plans: list = dataclasses.field(default_factory=list)
    weights: dict = dataclasses.field(default_factory=dict)
    first_threat: Any = None
    current_threat: Any = None
    diagnostics: dict = dataclasses.field(default_factory=dict)
    """Each node's last status: name → (level, message)."""
    finished: bool = False
    log: IncidentLog = dataclasses.field(default_factory=IncidentLog)
    heard: dict = dataclasses.field(default_factory=dict)
    """Each node's last status arrival: name → (wall-clock monotonic s, simulated s or None)."""
    pace: list = dataclasses.field(default_factory=list)
    """(wall-clock monotonic s, simulated s) of the first and the last odometry sample."""
    invalid: int = 0
    """Invalid plans and threats dropped (moose_ros.convert validates them)."""
    acknowledge: Optional[Callable[[float], None]] = None
    """Lockstep: called with the simulated time of each :data:`~moose_ros.lockstep.MONITOR_ACK_EVERY`-th tick of
    odometry read, and of the run's last (the monitor's marker: the simulator keeps at most
    :data:`~moose_ros.lockstep.MONITOR_LAG` ticks ahead of it)."""

    def attach(self, node: NodeBase) -> None:  # a tool that must not miss a sample (graph.Topic.tool_qos)
        callbacks = {ODOM.name: self.on_odom, STEERING.name: lambda m: setattr(self, "delta", m.delta),
                     PLAN_MPC.name: self.on_mpc, THREAT.name: self.on_threat, DIAGNOSTICS.name: self.on_diagnostics,
                     BLEND.name: lambda m: self.weights.__setitem__(cv.time_of(m), m.weight_mpc)}
        for name in MONITORED:  # a lockstep graph waits for these readers too (moose_ros.lockstep.MONITORED)
            TOPICS[name].tool_subscription(node, callbacks[name])

    def on_odom(self, m: Any) -> None:
        p, q, v = m.pose.pose.position, m.pose.pose.orientation, m.twist.twist.linear
        yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
        t = cv.time_of(m)
        self.odom.append((t, p.x, p.y, yaw, v.x, v.y, self.delta))
        now = (time.monotonic(), t)
        self.pace = [self.pace[0] if self.pace else now, now]
        if self.acknowledge is not None:
            end = self.scenario.end_time
            if tick_of(t, self.config.motion_period) % MONITOR_ACK_EVERY == 0 or t >= end - 1e-9:
                self.acknowledge(t)

    @property
    def sim_time(self) -> Optional[float]:
        """The newest simulated time seen on /vehicle/odom (``None`` before the first sample)."""
        return self.odom[-1][0] if self.odom else None

    def real_time_factor(self) -> Optional[float]:
        """Simulated seconds per wall-clock second between the first and the last odometry sample (``None``
        over less than 0.2 s of wall-clock time)."""
        if len(self.pace) < 2 or self.pace[1][0] - self.pace[0][0] < 0.2:
            return None
        return (self.pace[1][1] - self.pace[0][1]) / (self.pace[1][0] - self.pace[0][0])

    def on_mpc(self, m: Any) -> None:
        try:
            t, _, plan = cv.stamped_plan_from_msg(m)
            self.plans.append((t, plan, self.current_threat))
        except cv.InvalidMessage:
            self.invalid += 1

    def on_threat(self, m: Any) -> None:
        try:
            self.current_threat = cv.threat_from_msg(m)
        except cv.InvalidMessage:
            self.invalid += 1
            return
        if self.current_threat is not None and self.first_threat is None:
            self.first_threat = self.current_threat

    def on_diagnostics(self, m: Any) -> None:
        for status in m.status:
            level = status.level if isinstance(status.level, int) else status.level[0]
            self.diagnostics[status.name] = (level, status.message)
            self.heard[status.name] = (time.monotonic(), self.sim_time)
            self.log.on_status(self.sim_time, status.name, level, status.message,
                               {kv.key: kv.value for kv in status.values})
            if status.name == "vehicle_simulator" and status.message.startswith("finished"):
                self.finished = True

    def result(self, planner: PlannerMode, seed: int) -> SimulationResult:
        rows = np.array(sorted(self.odom)) if self.odom else np.zeros((0, 7))  # no odometry: judged incomplete
        trace = {name: rows[:, i] for i, name in enumerate(("t", "x", "y", "theta", "vx", "vy", "delta"))}
        planning = [
            PlanningRecord(t, threat, plan, None, Blend(self.weights.get(t, float("nan")), plan.accel),
                           Reference(0.0, 0.0), float("nan"))
            for t, plan, threat in self.plans
        ]
        return SimulationResult(self.scenario, planner, seed, trace, planning, self.first_threat,
                                self.config, self.scenario.end_time)
