"""Launch the node graph as separate OS processes without ROS 2 (``moose launch``).

Each node runs as ``python -m moose_ros.nodes NAME``; their output is streamed with a
``[name]`` prefix.  A monitor in this process listens to the graph (odometry, steering,
plans, blends, threats, diagnostics) and builds the same summary as ``moose simulate``.
The run ends when the simulator finishes (or, without a simulator, after ``duration``);
Ctrl-C / SIGTERM stop every child (SIGTERM, then SIGKILL after a grace period).
With ``bag`` set, every topic of the graph is recorded into that bag directory.
A node that dies is reported, and the rest of the graph keeps running.
"""
from __future__ import annotations

import dataclasses
import math
import os
import signal
import subprocess
import sys
import threading
import time
from typing import Any, Optional

import numpy as np

from moose.config import load_config
from moose.metrics import summarize
from moose.scenario import Scenario
from moose.signals import Blend, Reference
from moose.planning import PlanningRecord
from moose.schema import Config
from moose.simulation import SimulationResult

from . import convert as cv
from .bag import Recorder
from .runtime import QOS_DEFAULT, QOS_SENSOR, DdsNode

GRAPHS = {
    "full": ["vehicle_simulator", "observer", "obstacle_detector", "mpc_planner", "msf_planner", "weight_fbl",
             "motion_controller"],
    "car": ["observer", "obstacle_detector", "mpc_planner", "msf_planner", "weight_fbl", "motion_controller",
            "can_bridge"],
    "can": ["vehicle_simulator", "observer", "obstacle_detector", "mpc_planner", "msf_planner", "weight_fbl",
            "motion_controller", "can_bridge"],
}
"""``full``: with the vehicle simulator on topics; ``car``: the graph that runs on the vehicle (sensors and
actuators through the CAN bridge); ``can``: ``car`` plus the simulator as the vehicle-side ECU emulator
behind the DBC, over ``udp_multicast`` here."""


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
    finished: bool = False

    def attach(self, node: DdsNode) -> None:
        node.subscription("nav_msgs/msg/Odometry", "/vehicle/odom", self.on_odom, QOS_SENSOR)
        node.subscription("moose_msgs/msg/SteeringReport", "/vehicle/steering", lambda m: setattr(self, "delta", m.delta), QOS_SENSOR)
        node.subscription("moose_msgs/msg/PlannerOutput", "/planning/mpc", self.on_mpc, QOS_DEFAULT)
        node.subscription("moose_msgs/msg/Blend", "/planning/blend", lambda m: self.weights.__setitem__(cv.time_of(m), m.weight_mpc), QOS_DEFAULT)
        node.subscription("moose_msgs/msg/Threat", "/perception/threat", self.on_threat, QOS_DEFAULT)
        node.subscription("diagnostic_msgs/msg/DiagnosticArray", "/diagnostics", self.on_diagnostics, QOS_DEFAULT)

    def on_odom(self, m: Any) -> None:
        p, q, v = m.pose.pose.position, m.pose.pose.orientation, m.twist.twist.linear
        yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
        self.odom.append((cv.time_of(m), p.x, p.y, yaw, v.x, v.y, self.delta))

    def on_mpc(self, m: Any) -> None:
        self.plans.append((cv.time_of(m), cv.plan_from_msg(m), self.current_threat))

    def on_threat(self, m: Any) -> None:
        self.current_threat = cv.threat_from_msg(m)
        if self.current_threat is not None and self.first_threat is None:
            self.first_threat = self.current_threat

    def on_diagnostics(self, m: Any) -> None:
        for status in m.status:
            level = status.level if isinstance(status.level, int) else status.level[0]
            self.diagnostics[status.name] = (level, status.message)
            if status.name == "vehicle_simulator" and status.message == "finished":
                self.finished = True

    def result(self, planner: str, seed: int) -> SimulationResult:
        rows = np.array(sorted(self.odom)) if self.odom else np.zeros((0, 7))  # no odometry: judged incomplete
        trace = {name: rows[:, i] for i, name in enumerate(("t", "x", "y", "theta", "vx", "vy", "delta"))}
        planning = [
            PlanningRecord(t, threat, plan, None, Blend(self.weights.get(t, float("nan")), plan.accel), Reference(0.0, 0.0), float("nan"))
            for t, plan, threat in self.plans
        ]
        return SimulationResult(self.scenario, planner, seed, trace, planning, self.first_threat,  # type: ignore[arg-type]
                                self.config, self.scenario.lead_time + self.scenario.duration)


def launch(
    scenario: Scenario,
    scenario_params: dict[str, Any],
    graph: str = "full",
    planner: str = "combined",
    seed: int = 0,
    params_file: Optional[str] = None,
    rate: float = 1.0,
    duration: Optional[float] = None,
    kill_after: Optional[tuple[str, float]] = None,
    out=sys.stdout,
    bag: Optional[Any] = None,
    can_params: Optional[dict[str, Any]] = None,
) -> dict[str, Any]:
    """Run the graph once and return the summary (plus ``node_exits`` and ``diagnostics``)."""
    nodes = [n for n in GRAPHS[graph] if not (planner == "mpc" and n == "msf_planner") and not (planner == "msf" and n == "mpc_planner")]
    common = dict(scenario_params, seed=seed, planner=planner, **(can_params or {}))
    procs: dict[str, subprocess.Popen] = {}
    lock = threading.Lock()

    def stream(name: str, proc: subprocess.Popen) -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            with lock:
                out.write(f"[{name}] {line}")
                out.flush()

    for name in nodes:
        # simulated time only when the simulator is there to publish /clock (not on the car)
        overrides = dict(common, use_sim_time="vehicle_simulator" in nodes and name != "vehicle_simulator")
        if name == "vehicle_simulator":
            overrides["rate"] = rate
            overrides["vehicle_bus"] = "can" if "can_bridge" in nodes else "topics"
            overrides["wait_for"] = "[" + ", ".join(n for n in nodes if n != name) + "]"
        cmd = [sys.executable, "-m", "moose_ros.nodes", name]
        if params_file:
            cmd += ["--params", params_file]
        for key, value in overrides.items():
            cmd += ["--param", f"{key}={value}"]
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=os.environ.copy())
        procs[name] = proc
        threading.Thread(target=stream, args=(name, proc), daemon=True).start()

    monitor = Monitor(scenario, scenario.configure(load_config(params_file)))
    node = DdsNode("moose_monitor", overrides={"use_sim_time": False})
    monitor.attach(node)
    recorder = Recorder(node, bag) if bag is not None else None
    exits: dict[str, int] = {}
    limit = time.monotonic() + (duration if duration is not None else (scenario.lead_time + scenario.duration) / rate + 60.0)
    stop = threading.Event()
    previous = {sig: signal.signal(sig, lambda *_: stop.set()) for sig in (signal.SIGINT, signal.SIGTERM)} \
        if threading.current_thread() is threading.main_thread() else {}
    try:
        while not stop.is_set() and time.monotonic() < limit:
            node.spin_once(0.05)
            sim_time = monitor.odom[-1][0] if monitor.odom else -1.0
            if kill_after and kill_after[0] in procs and sim_time >= kill_after[1] and kill_after[0] not in exits:
                procs[kill_after[0]].kill()  # fault injection for tests: SIGKILL at a simulated time
            for name, proc in procs.items():
                code = proc.poll()
                if code is not None and name not in exits:
                    exits[name] = code
                    if name != "vehicle_simulator":
                        with lock:
                            out.write(f"[launch] node {name} exited with status {code}; the graph keeps running\n")
            if "vehicle_simulator" in exits:
                break
            if monitor.finished:
                limit = min(limit, time.monotonic() + 15.0)  # the simulator is closing down
        for _ in range(10):  # let the last messages arrive
            node.spin_once(0.02)
    finally:
        for proc in procs.values():
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + 5.0
        for name, proc in procs.items():
            try:
                proc.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
            exits.setdefault(name, proc.returncode)
        node.shutdown()
        if recorder is not None:
            recorder.close()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    summary = summarize(monitor.result(planner, seed))
    summary["node_exits"] = exits
    summary["diagnostics"] = {k: {"level": v[0], "message": v[1]} for k, v in monitor.diagnostics.items()}
    summary["odom_samples"] = len(monitor.odom)
    return summary

