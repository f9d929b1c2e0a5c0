"""Launch the node graph as separate OS processes without ROS 2 (``moose launch``).

Each node runs as ``python -m moose_ros.nodes NAME``; their output is streamed with a
``[name]`` prefix.  ``runtime`` chooses what the nodes run on (:mod:`moose_ros.runtime`: ``rclpy``
or ``dds``, for all or per node; default: this interpreter's); a node on rclpy that this
interpreter cannot run is started with the interpreter and environment of the ROS 2 prefix of
``make ros`` (:func:`moose_ros.runtime.process`).  A monitor in this process listens to the graph
(odometry, steering, plans, blends, threats, diagnostics) and builds the same summary as
``moose simulate``; it runs on the nodes' runtime when this interpreter can run it, else (and for a
mixed graph) on Cyclone DDS, which then needs discovery settings that match the nodes' (README).
The run ends when the simulator finishes (or, without a simulator, after ``duration``);
Ctrl-C / SIGTERM stop every child (SIGTERM, then SIGKILL after a grace period).
With ``bag`` set, every topic of the graph is recorded into that bag directory.
A node that dies is reported, and the rest of the graph keeps running.
"""
from __future__ import annotations

import dataclasses
import json
import math
import signal
import subprocess
import sys
import threading
import time
from typing import Any, Mapping, Optional, Union

import numpy as np

from moose.config import load_config
from moose.metrics import summarize
from moose.params import ParamError, read_ros_params
from moose.planning import PlanningRecord
from moose.scenario import Scenario
from moose.schema import Config, PlannerMode
from moose.signals import Blend, Reference
from moose.simulation import SimulationResult

from . import convert as cv
from .bag import Recorder
from .bag.params import RunParameters
from .graph import BLEND, DIAGNOSTICS, GRAPHS, ODOM, PLAN_MPC, STEERING, THREAT
from .parameters import check_parameter_file, node_parameters, parameter_names
from .runtime import create_node, process, rclpy_missing
from .runtime.base import set_dotted


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
    invalid: int = 0
    """Invalid plans and threats dropped (moose_ros.convert validates them)."""

    def attach(self, node: Any) -> None:  # a tool that must not miss a sample (graph.Topic.tool_qos)
        ODOM.tool_subscription(node, self.on_odom)
        STEERING.tool_subscription(node, lambda m: setattr(self, "delta", m.delta))
        PLAN_MPC.tool_subscription(node, self.on_mpc)
        BLEND.tool_subscription(node, lambda m: self.weights.__setitem__(cv.time_of(m), m.weight_mpc))
        THREAT.tool_subscription(node, self.on_threat)
        DIAGNOSTICS.tool_subscription(node, self.on_diagnostics)

    def on_odom(self, m: Any) -> None:
        p, q, v = m.pose.pose.position, m.pose.pose.orientation, m.twist.twist.linear
        yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
        self.odom.append((cv.time_of(m), p.x, p.y, yaw, v.x, v.y, self.delta))

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
            if status.name == "vehicle_simulator" and status.message == "finished":
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
                                self.config, self.scenario.lead_time + self.scenario.duration)


def _file_params(params_file: Optional[str], node: str) -> dict[str, Any]:
    return read_ros_params(params_file, node) if params_file else {}


def planner_mode(planner: Optional[PlannerMode], params_file: Optional[str]) -> PlannerMode:
    """``planner``, or the mode ``weight_fbl`` reads from the parameter file (``simulation.planner``)."""
    if params_file:
        check_parameter_file(params_file)
    return planner or node_parameters("weight_fbl", _file_params(params_file, "weight_fbl"))[0].simulation.planner


def node_overrides(graph: str, planner: str, params: Optional[dict[str, Any]] = None,
                   params_file: Optional[str] = None, seed: int = 0, rate: float = 1.0) -> dict[str, dict[str, Any]]:
    """Each node's parameter overrides for one run of ``graph`` with ``planner``, checked before anything starts.

    ``params`` go to every node that takes them (:mod:`moose_ros.parameters`; dotted keys of the core's
    groups go to all); a key that no node of the graph takes is an error, and so is any parameter that a node
    would refuse (the file's values included), so a bad configuration stops the launch before a node runs.
    The planner node that ``planner`` does not use is left out.
    """
    nodes = [n for n in GRAPHS[graph] if not (planner == "mpc" and n == "msf_planner")
             and not (planner == "msf" and n == "mpc_planner")]
    given = dict(params or {}, **{"simulation.planner": planner})
    simulated = "vehicle_simulator" in nodes
    if simulated:
        given.update(seed=seed, rate=rate, vehicle_bus="can" if "can_bridge" in nodes else "topics")
    if "can_interface" in given:
        from moose.canbus.bus import INTERFACES

        if given["can_interface"] not in INTERFACES:
            raise ParamError(f"can_interface = {given['can_interface']!r} is invalid: "
                             f"expected one of {list(INTERFACES)}")
    taken = set().union(*(parameter_names(n) for n in nodes))
    unknown = sorted(k for k in given if "." not in k and k not in taken)
    if unknown:
        raise ParamError(f"{unknown[0]} = {given[unknown[0]]!r} is taken by no node of the graph {graph!r} "
                         f"({', '.join(nodes)})")
    out: dict[str, dict[str, Any]] = {}
    for name in nodes:
        own = parameter_names(name)
        overrides = {k: v for k, v in given.items() if "." in k or k in own}
        # simulated time only when the simulator is there to publish /clock (not on the car)
        overrides["use_sim_time"] = simulated and name != "vehicle_simulator"
        if name == "vehicle_simulator":
            overrides["wait_for"] = [n for n in nodes if n != name]
        merged = _file_params(params_file, name)
        for key, value in overrides.items():
            set_dotted(merged, key, value)
        node_parameters(name, merged)  # refuses what the node would refuse
        out[name] = overrides
    return out


def launch(
    scenario: Scenario,
    params: dict[str, Any],
    graph: str = "full",
    planner: Optional[PlannerMode] = None,
    seed: int = 0,
    params_file: Optional[str] = None,
    rate: float = 1.0,
    duration: Optional[float] = None,
    kill_after: Optional[tuple[str, float]] = None,
    out=sys.stdout,
    bag: Optional[Any] = None,
    foxglove: Optional[tuple[str, int]] = None,
    runtime: Union[None, str, Mapping[str, str]] = None,
) -> dict[str, Any]:
    """Run the graph once and return the summary (plus ``node_exits``, ``diagnostics`` and ``runtime``:
    what each node and the monitor ran on).

    ``runtime``: ``rclpy`` or ``dds`` for every node, or ``{node: runtime}`` (others: the default).

    ``params``: node parameters (``scenario`` or the ad-hoc ``speed``/``tau``/…, ``can_interface``, …) given
    to every node that takes them; see :func:`node_overrides`.  ``foxglove``: (host, port) of a live view
    (:class:`moose_ros.live.LiveView`) served while the graph runs."""
    planner = planner_mode(planner, params_file)
    if scenario.mu is not None:  # the road of this run, for every node: one friction in the whole graph
        params = {"vehicle.mu": scenario.mu, **params}
    overrides = node_overrides(graph, planner, params, params_file, seed, rate)
    children = {name: process(runtime.get(name) if isinstance(runtime, Mapping) else runtime) for name in overrides}
    runtimes = {name: env["MOOSE_RUNTIME"] for name, (_python, env) in children.items()}
    # the monitor: on the nodes' runtime when this interpreter can run it, else (and for a mixed graph) on Cyclone
    runtimes["moose_monitor"] = "rclpy" if set(runtimes.values()) == {"rclpy"} and not rclpy_missing() else "dds"
    monitor = Monitor(scenario, scenario.configure(load_config(params_file)))
    node = create_node("moose_monitor", overrides={"use_sim_time": False}, runtime=runtimes["moose_monitor"])
    monitor.attach(node)
    recorder = live = None
    try:
        run = RunParameters(monitor.config, scenario, planner, seed)  # kept in the bag (moose bag replan uses it)
        recorder = Recorder(node, bag, parameters=run) if bag is not None else None  # an unusable path stops here
        if foxglove is not None:
            from .live import LiveView

            live = LiveView(node, host=foxglove[0], port=foxglove[1])
            out.write(f"[launch] Foxglove live view on {live.url}\n")
    except Exception:
        if recorder is not None:
            recorder.close()
        node.shutdown()
        raise
    procs: dict[str, subprocess.Popen] = {}
    lock = threading.Lock()

    def stream(name: str, proc: subprocess.Popen) -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            with lock:
                out.write(f"[{name}] {line}")
                out.flush()

    for name, given in overrides.items():
        python, env = children[name]
        cmd = [python, "-m", "moose_ros.nodes", name]
        if params_file:
            cmd += ["--params", params_file]
        for key, value in given.items():
            cmd += ["--param", f"{key}={json.dumps(value)}"]
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
        procs[name] = proc
        threading.Thread(target=stream, args=(name, proc), daemon=True).start()

    exits: dict[str, int] = {}
    limit = time.monotonic() + (duration if duration is not None
                                else (scenario.lead_time + scenario.duration) / rate + 60.0)
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
        if live is not None:
            live.close()
        node.shutdown()
        if recorder is not None:
            recorder.close()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    summary = summarize(monitor.result(planner, seed))
    summary["node_exits"] = exits
    summary["diagnostics"] = {k: {"level": v[0], "message": v[1]} for k, v in monitor.diagnostics.items()}
    summary["odom_samples"] = len(monitor.odom)
    summary["invalid_messages"] = monitor.invalid
    summary["runtime"] = runtimes
    return summary

