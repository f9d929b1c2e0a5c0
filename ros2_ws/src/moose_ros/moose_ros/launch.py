"""Launch the node graph as separate OS processes without ROS 2 (``moose launch``).

Each node runs as ``python -m moose_ros.nodes NAME``, started by :func:`moose_ros.process.spawn` (it dies
with the launcher, even a SIGKILLed one); their output is streamed with a ``[name]`` prefix.  ``runtime``
chooses what the nodes run on (:mod:`moose_ros.runtime`: ``rclpy`` or ``dds``, for all or per node; default:
this interpreter's); a node on rclpy that this interpreter cannot run is started with the interpreter and
environment of the ROS 2 prefix of ``make ros`` (:func:`moose_ros.runtime.process`).  The monitor runs on the
nodes' runtime when this interpreter can run it, else (and for a mixed graph) on Cyclone DDS, which then
needs discovery settings that match the nodes' (README).  Before any
node starts, the parameters are checked (:func:`node_overrides`) and the DDS domain is checked for nodes
of another graph (:func:`check_domain`: a run left over on the same domain would mix its messages into
this one).  A monitor in this process listens to the graph (odometry, steering, plans, blends, threats,
diagnostics) and builds the same summary as ``moose simulate``, plus what only a graph has
(:mod:`moose_ros.incidents`): every node's exit status and end, every incident (a node that failed to
start, died or stalled, a stale input, a minimum-risk maneuver, a planner fallback, deadline misses, a
rate not held), the achieved real-time factor, and the exit status.  The outcome is the verdict on
/vehicle/odom (:func:`moose.verdict.judge`): too little odometry is ``incomplete``, and so is any run cut
short (Ctrl-C, SIGTERM, a node that failed to start, the simulator gone) that did not fail outright.
The run ends when the simulator finishes (or, without a simulator, after ``duration``); then every child
gets SIGTERM (SIGKILL after a grace period), on which a node ends with status 0.  ``faults`` kill or stall
nodes at given simulated times (:mod:`moose_ros.faults`).  With ``bag`` set, every topic of the graph is
recorded into that bag directory.  A node that dies is reported, and the rest of the graph keeps running.
"""
from __future__ import annotations

import dataclasses
import json
import math
import os
import signal
import subprocess
import sys
import threading
import time
from typing import Any, Mapping, Optional, Sequence, Union

import numpy as np

from moose.config import load_config, with_overrides
from moose.metrics import summarize
from moose.params import ParamError, read_ros_params
from moose.planner import MODE_PLANNERS
from moose.planner.step import PlanningRecord
from moose.scenario import Scenario
from moose.schema import Config, PlannerMode
from moose.signals import Blend, Reference
from moose.simulation import SimulationResult
from moose.verdict import exit_status

from . import convert as cv
from .bag import Recorder
from .bag.params import RunParameters
from .faults import Fault, FaultInjector
from .graph import BLEND, DIAGNOSTICS, GRAPHS, NODES, ODOM, PLAN_MPC, STEERING, THREAT, TOPICS
from .incidents import RATE_TOLERANCE, IncidentLog
from .lockstep import MONITORED, STUCK_TIMEOUT, sensor_transit
from .parameters import check_parameter_file, node_parameters, parameter_names
from .process import spawn
from .runtime import create_node, process, rclpy_missing
from .runtime.base import set_dotted

STOP_GRACE = 5.0
"""Seconds a node has to end after SIGTERM before it gets SIGKILL."""
DOMAIN_CHECK = 1.0
"""Seconds the launcher listens for other nodes in its DDS domain before it starts any (:func:`check_domain`)."""
MONITOR_NAME = "moose_monitor"
LOCKSTEP_MIN_RATE = 0.05
"""The slowest lockstep run the launcher waits for (simulated seconds per wall-clock second), beyond start-up."""


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

    def attach(self, node: Any) -> None:  # a tool that must not miss a sample (graph.Topic.tool_qos)
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
                                self.config, self.scenario.lead_time + self.scenario.duration)


def _file_params(params_file: Optional[str], node: str) -> dict[str, Any]:
    return read_ros_params(params_file, node) if params_file else {}


def planner_mode(planner: Optional[PlannerMode], params_file: Optional[str]) -> PlannerMode:
    """``planner``, or the mode ``weight_fbl`` reads from the parameter file (``simulation.planner``)."""
    if params_file:
        check_parameter_file(params_file)
    return planner or node_parameters("weight_fbl", _file_params(params_file, "weight_fbl"))[0].simulation.planner


def node_overrides(graph: str, planner: str, params: Optional[dict[str, Any]] = None,
                   params_file: Optional[str] = None, seed: int = 0, rate: float = 1.0, lockstep: bool = False,
                   faults: Sequence[Fault] = ()) -> dict[str, dict[str, Any]]:
    """Each node's parameter overrides for one run of ``graph`` with ``planner``, checked before anything starts.

    ``params`` go to every node that takes them (:mod:`moose_ros.parameters`; dotted keys of the core's
    groups go to all); a key that no node of the graph takes is an error, and so is any parameter that a node
    would refuse (the file's values included), so a bad configuration stops the launch before a node runs.
    The planner node that ``planner`` does not use is left out (:data:`moose.planner.MODE_PLANNERS`: a baseline runs
    in ``msf_planner``, without ``mpc_planner``).  ``lockstep``: every node gets the graph's nodes
    (``lockstep_nodes``, :mod:`moose_ros.lockstep`) and runs on the ticks, not on a clock; the simulator gets the
    ``faults`` (its fault plan).
    """
    if params_file:
        check_parameter_file(params_file, GRAPHS[graph], graph)
    if planner not in MODE_PLANNERS:
        raise ParamError(f"planner = {planner!r} is invalid: expected one of {list(MODE_PLANNERS)}")
    unused = {f"{slot}_planner" for slot in ("mpc", "msf") if slot not in MODE_PLANNERS[planner]}
    nodes = [n for n in GRAPHS[graph] if n not in unused]
    given = dict(params or {}, **{"simulation.planner": planner})
    simulated = "vehicle_simulator" in nodes
    if lockstep and not simulated:
        raise ParamError(f"--lockstep needs the vehicle simulator: the graph {graph!r} has none (the car runs in "
                         "real time)")
    if simulated:
        given.update(seed=seed, rate=rate, vehicle_bus="can" if "can_bridge" in nodes else "topics")
    if lockstep:
        given["lockstep_nodes"] = list(nodes)
        given["lockstep_monitor"] = True  # this launcher's monitor reads the graph: nothing of tick 0 passes it by
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
        # simulated time only when the simulator is there to publish /clock (not on the car); in lockstep each
        # node's time is the tick it handles
        overrides["use_sim_time"] = simulated and name != "vehicle_simulator" and not lockstep
        if name == "vehicle_simulator":
            overrides["wait_for"] = [n for n in nodes if n != name]
            if lockstep and faults:
                overrides["faults"] = [str(f) for f in faults]
        merged = _file_params(params_file, name)
        for key, value in overrides.items():
            set_dotted(merged, key, value)
        config, own = node_parameters(name, merged)  # refuses what the node would refuse
        if name == "vehicle_simulator" and lockstep:
            sensor_transit(config, own.vehicle_bus, True)  # the CAN graph's hop is a tick: no shorter sensor delay
        out[name] = overrides
    return out


def check_domain(node: Any, wait: float = DOMAIN_CHECK) -> None:
    """Refuse to start a graph in a DDS domain where nodes of another moose graph run (a run whose launcher
    was killed, or another launch): their messages would mix with this run's.  Listens ``wait`` seconds
    to ``ros_discovery_info`` through ``node``; a :class:`ParamError` names the nodes found."""
    deadline = time.monotonic() + wait
    found: list[tuple[str, str]] = []
    while time.monotonic() < deadline:
        node.spin_once(0.05)
        found = [n for n in node.node_names() if n[1] in NODES or n[1] == MONITOR_NAME]
        if found:
            break
    if found:
        names = ", ".join(f"{ns.rstrip('/')}/{name}" for ns, name in found)
        domain = os.environ.get("ROS_DOMAIN_ID", "0") or "0"
        raise ParamError(f"DDS domain {domain} (ROS_DOMAIN_ID) already has nodes of a moose graph: {names}; "
                         "a graph left from an earlier run, or another launch: stop it (moose launch stops its "
                         "nodes when it ends or is killed) or use another ROS_DOMAIN_ID")


def launch(
    scenario: Scenario,
    params: dict[str, Any],
    graph: str = "full",
    planner: Optional[PlannerMode] = None,
    seed: int = 0,
    params_file: Optional[str] = None,
    rate: float = 1.0,
    duration: Optional[float] = None,
    faults: Sequence[Fault] = (),
    out=sys.stdout,
    bag: Optional[Any] = None,
    foxglove: Optional[tuple[str, int]] = None,
    runtime: Union[None, str, Mapping[str, str]] = None,
    lockstep: bool = False,
) -> dict[str, Any]:
    """Run the graph once and return the summary: the keys of ``moose simulate``'s, plus ``node_exits``,
    ``node_status``, ``incidents``, ``degraded``, ``deadline_misses``, ``stalls``, ``real_time_factor``,
    ``interrupted``, ``faults``, ``diagnostics``, ``odom_samples``, ``final_position_m``, ``final_speed_mps``,
    ``invalid_messages``, ``runtime`` (what each node and the monitor ran on) and ``exit_status``
    (:func:`moose_ros.incidents.exit_status`).

    ``runtime``: ``rclpy`` or ``dds`` for every node, or ``{node: runtime}`` (others: the default).

    ``params``: node parameters (``scenario`` or the ad-hoc ``speed``/``tau``/…, ``can_interface``, …) given
    to every node that takes them; see :func:`node_overrides`.  ``faults``: the faults to inject
    (:class:`moose_ros.faults.Fault`).  ``foxglove``: (host, port) of a live view
    (:class:`moose_ros.live.LiveView`) served while the graph runs.  ``lockstep``: the graph steps simulated time
    only when every node has handled the tick (:mod:`moose_ros.lockstep`); ``rate`` is then not used, and the
    faults act at their simulated times."""
    planner = planner_mode(planner, params_file)
    if scenario.mu is not None:  # the road of this run, for every node: one friction in the whole graph
        params = {"vehicle.mu": scenario.mu, **params}
    overrides = node_overrides(graph, planner, params, params_file, seed, rate, lockstep, faults)
    for fault in faults:
        if fault.node not in overrides:
            raise ParamError(f"--fault {str(fault)!r} is invalid: {fault.node!r} is not a node of this run "
                             f"({', '.join(overrides)})")
    simulated = "vehicle_simulator" in overrides
    children = {name: process(runtime.get(name) if isinstance(runtime, Mapping) else runtime) for name in overrides}
    runtimes = {name: env["MOOSE_RUNTIME"] for name, (_python, env) in children.items()}
    # the monitor: on the nodes' runtime when this interpreter can run it, else (and for a mixed graph) on Cyclone
    runtimes[MONITOR_NAME] = "rclpy" if set(runtimes.values()) == {"rclpy"} and not rclpy_missing() else "dds"
    # what the nodes run with: the file, then the values given to every node (timing, friction belief, --set)
    shared = {key: value for key, value in params.items() if "." in key}
    monitor = Monitor(scenario, scenario.configure(with_overrides(load_config(params_file, reader=None), shared)))
    node = create_node(MONITOR_NAME, overrides={"use_sim_time": False}, runtime=runtimes[MONITOR_NAME])
    recorder = live = None
    try:
        check_domain(node)
        monitor.attach(node)
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
    last_lines: dict[str, list[str]] = {}
    lock = threading.Lock()

    def say(text: str) -> None:
        with lock:
            out.write(f"[launch] {text}\n")
            out.flush()

    def stream(name: str, proc: subprocess.Popen) -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            with lock:
                out.write(f"[{name}] {line}")
                out.flush()
                last_lines[name] = (last_lines.get(name, []) + [line.rstrip()])[-3:]

    log = monitor.log
    exits: dict[str, int] = {}
    ends: dict[str, str] = {}
    stop = threading.Event()
    interrupted: list[str] = []

    def on_signal(signum: int, _frame: Any) -> None:
        interrupted.append(signal.Signals(signum).name)
        stop.set()

    previous = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)} \
        if threading.current_thread() is threading.main_thread() else {}
    injector = FaultInjector(faults, procs, rate, log, say, lockstep=lockstep)
    silent: set[str] = set()
    cut_short = ""
    try:
        for name, given in overrides.items():
            python, env = children[name]
            cmd = [python, "-m", "moose_ros.nodes", name]
            if params_file:
                cmd += ["--params", params_file]
            for key, value in given.items():
                cmd += ["--param", f"{key}={json.dumps(value)}"]
            proc = spawn(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
            procs[name] = proc
            threading.Thread(target=stream, args=(name, proc), daemon=True).start()
        start = time.monotonic()
        planned = scenario.lead_time + scenario.duration
        # with the simulator: its run at ``rate`` plus its start-up (it waits up to a minute for the nodes); without
        # (the car): the planned run on the wall clock
        if lockstep:  # as fast as the graph goes; a graph that stops going ends itself (lockstep_stuck)
            limit = start + (duration if duration is not None else planned / LOCKSTEP_MIN_RATE + 60.0 + STUCK_TIMEOUT)
        else:
            limit = start + (duration if duration is not None else planned / rate + 60.0 if simulated else planned)
        while not stop.is_set() and time.monotonic() < limit:
            node.spin_once(0.05)
            t_sim = monitor.sim_time
            t_fault = t_sim if simulated else time.monotonic() - start
            if t_fault is not None:
                injector.poll(t_fault)
            for name, proc in procs.items():
                code = proc.poll()
                if code is None or name in exits:
                    continue
                exits[name] = code
                if name not in log.announced:
                    ends[name] = f"failed to start ({_status_text(code)})"
                    detail = " | ".join(last_lines.get(name, [])) or "no output"
                    log.add(t_sim, name, "failed_to_start", f"exited with {_status_text(code)} before it "
                                                            f"announced itself: {detail}")
                elif name == "vehicle_simulator" and code == 0 and monitor.finished:
                    ends[name] = "finished"
                else:
                    ends[name] = f"died ({_status_text(code)})"
                    log.add(t_sim, name, "died", f"exited with {_status_text(code)} during the run"
                            + (" (the injected fault)" if name in injector.killed else ""))
                    say(f"node {name} exited with status {code}; the graph keeps running")
            failed = [n for n, e in ends.items() if e.startswith("failed to start")]
            if failed:
                cut_short = f"{', '.join(failed)} failed to start"
                break
            if "vehicle_simulator" in exits:
                if not monitor.finished:
                    cut_short = "the simulator ended before the run did"
                break
            _watch_heartbeats(monitor, procs, exits, overrides, silent)
            if monitor.finished:
                limit = min(limit, time.monotonic() + 15.0)  # the simulator is closing down
        else:
            if stop.is_set():
                cut_short = f"{interrupted[0] if interrupted else 'a signal'} to the launcher"
            elif simulated and not monitor.finished:
                cut_short = "the time limit of the run was reached"
        for _ in range(10):  # let the last messages arrive
            node.spin_once(0.02)
    finally:
        injector.release()
        _stop_children(procs, exits, ends, log, node, monitor)
        if live is not None:
            live.close()
        node.shutdown()
        if recorder is not None:
            recorder.close()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    summary = _summary(monitor, planner, seed, None if lockstep else rate, exits, ends, faults, cut_short,
                       interrupted)
    summary["lockstep"] = lockstep
    summary["runtime"] = runtimes
    summary["bag_error"] = recorder.error if recorder is not None else None  # the recording, not the run
    return summary


def _status_text(code: int) -> str:
    if code < 0:
        try:
            return f"signal {signal.Signals(-code).name}"
        except ValueError:
            return f"signal {-code}"
    return f"exit status {code}"


def _watch_heartbeats(monitor: Monitor, procs: dict[str, subprocess.Popen], exits: dict[str, int],
                      overrides: dict[str, dict[str, Any]], silent: set[str]) -> None:
    """A running node silent on /diagnostics for longer than the topic's deadline (on its own clock: simulated
    time for the nodes on ``use_sim_time``, the wall clock for the others) is a ``stalled`` incident, once per
    silence."""
    deadline = DIAGNOSTICS.deadline
    assert deadline is not None
    now_wall, now_sim = time.monotonic(), monitor.sim_time
    for name in procs:
        if name in exits or name not in monitor.heard:
            continue
        wall, sim = monitor.heard[name]
        on_sim = bool(overrides[name].get("use_sim_time"))
        if on_sim and (now_sim is None or sim is None):
            continue
        quiet = (now_sim - sim) if on_sim else (now_wall - wall)
        if quiet > deadline and name not in silent:
            silent.add(name)
            monitor.log.add(now_sim, name, "stalled", f"silent on /diagnostics for {quiet:.1f} s "
                                                      f"({'simulated' if on_sim else 'wall-clock'} time)")
        elif quiet <= deadline:
            silent.discard(name)


def _stop_children(procs: dict[str, subprocess.Popen], exits: dict[str, int], ends: dict[str, str],
                   log: IncidentLog, node: Any, monitor: Monitor) -> None:
    """SIGCONT and SIGTERM to every running node, SIGKILL after :data:`STOP_GRACE`; the monitor keeps listening
    meanwhile (the nodes' final statuses carry their final counters)."""
    running = [name for name, proc in procs.items() if proc.poll() is None and name not in exits]
    for name in running:
        for sig in (signal.SIGCONT, signal.SIGTERM):
            try:
                procs[name].send_signal(sig)
            except ProcessLookupError:
                pass
    deadline = time.monotonic() + STOP_GRACE
    while time.monotonic() < deadline and any(procs[n].poll() is None for n in running):
        try:
            node.spin_once(0.05)
        except Exception:  # noqa: BLE001 - the monitor may be gone on an error path; the children still stop
            time.sleep(0.05)
    for name, proc in procs.items():
        if proc.poll() is None:
            proc.kill()
            proc.wait()
            if name in running:
                ends[name] = f"did not stop within {STOP_GRACE:g} s of SIGTERM: killed"
                log.add(monitor.sim_time, name, "died", ends[name])
        code = proc.returncode
        exits.setdefault(name, code)
        if name in running and name not in ends:
            if code == 0:
                ends[name] = "stopped"
            else:
                ends[name] = f"did not stop cleanly ({_status_text(code)})"
                log.add(monitor.sim_time, name, "died", ends[name])


def _summary(monitor: Monitor, planner: PlannerMode, seed: int, rate: Optional[float], exits: dict[str, int],
             ends: dict[str, str],
             faults: Sequence[Fault], cut_short: str, interrupted: list[str]) -> dict[str, Any]:
    log = monitor.log
    if cut_short:
        log.add(monitor.sim_time, "launch", "cut_short", cut_short)
    for name, counters in sorted(log.counters.items()):
        misses = int(counters.get("deadline_misses", 0))
        if misses:
            log.add(None, name, "deadline_missed", f"{misses} deadline misses (longest executor gap "
                                                   f"{counters.get('longest_gap_ms', 0):.0f} ms)")
    achieved = monitor.real_time_factor()
    if rate is not None and achieved is not None and achieved < RATE_TOLERANCE * rate:
        log.add(None, "vehicle_simulator", "rate_not_held",
                f"--rate {rate:g} not held: achieved {achieved:.2f} (below {RATE_TOLERANCE:g} × requested)")
    summary = summarize(monitor.result(planner, seed))
    if cut_short:
        if summary["outcome"] in ("clear", "stopped_short"):  # never a success from a run cut short
            summary["outcome"], summary["complete"] = "incomplete", False
        summary["reason"] = f"the run was cut short ({cut_short}); {summary['reason']}"
    last = monitor.odom[-1] if monitor.odom else None
    summary.update(
        node_exits=exits,
        node_status=ends,
        diagnostics={k: {"level": v[0], "message": v[1]} for k, v in monitor.diagnostics.items()},
        odom_samples=len(monitor.odom),
        final_position_m=None if last is None else [last[1], last[2]],
        final_speed_mps=None if last is None else math.hypot(last[4], last[5]),
        incidents=[i.as_dict() for i in log.incidents],
        degraded=log.degraded,
        deadline_misses={n: int(c.get("deadline_misses", 0)) for n, c in sorted(log.counters.items())},
        stalls={n: int(c.get("stalls", 0)) for n, c in sorted(log.counters.items())},
        real_time_factor={"requested": rate, "achieved": achieved},
        interrupted=interrupted[0] if interrupted else None,
        faults=[str(f) for f in faults],
        invalid_messages=monitor.invalid,
    )
    summary["exit_status"] = exit_status(summary["outcome"], summary["degraded"], summary["interrupted"])
    return summary
