"""Launch the node graph as separate OS processes without ROS 2 (``moose launch``).

Each node runs as ``python -m moose_ros.nodes NAME``, forked by the run's fork server (:mod:`moose_ros.forkserver`:
the imports and message classes every node needs, done once) or started by :func:`moose_ros.process.spawn` (it dies
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

:func:`launch` checks what it is given and hands the run to a :class:`Supervisor`, the one object that owns the
node processes, the monitor (:mod:`moose_ros.monitor`), the fault injector, the recorder and the live view.
"""
from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any, Iterator, Mapping, Optional, Sequence, TextIO, Union

from moose.config import load_config, with_overrides
from moose.metrics import summarize
from moose.params import ParamError, read_ros_params
from moose.planner import MODE_PLANNERS
from moose.scenario import Scenario
from moose.schema import PlannerMode
from moose.verdict import exit_status

from .bag import Recorder
from .bag.params import RunParameters
from .faults import Fault, FaultInjector
from .forkserver import ForkServer, shared
from .graph import DIAGNOSTICS, GRAPHS, NODES
from .incidents import RATE_TOLERANCE
from .live import LiveView
from .lockstep import (
    MONITOR,
    QOS_MARKER,
    STUCK_TIMEOUT,
    TICK_TYPE,
    check_stalls,
    marker_message,
    marker_topic,
    sensor_transit,
)
from .monitor import Monitor
from .nodes import STACK_DUMP
from .nodes import __name__ as NODES_MODULE
from .parameters import check_parameter_file, node_parameters, parameter_names
from .process import Child, spawn
from .runtime import create_node, process, rclpy_missing
from .runtime.base import NodeBase, set_dotted

STOP_GRACE = 20.0
"""Seconds a node has to end after SIGTERM before it gets SIGKILL.  A node normally ends within a second; the
grace only bounds a node that hangs, so it is generous: on a starved machine (a load average of 50 on 2 cores, a
fresh-clone CI beside four other jobs) nodes of a lockstep run that ended normally needed more than 5 s, and a
SIGKILL then made a correct run's node exits depend on the machine's speed."""
STACK_DUMP_WAIT = 1.0
"""Seconds a node that outlived :data:`STOP_GRACE` has to write its stacks (:data:`moose_ros.nodes.STACK_DUMP`)
before SIGKILL."""
DOMAIN_CHECK = 1.0
"""Seconds the launcher listens for other nodes in its DDS domain before it starts any (:func:`check_domain`)."""
LOCKSTEP_POLL = 0.02
"""In lockstep, the launcher takes what its node received every this many seconds of wall-clock time
(:meth:`Supervisor.listen`) rather than waking for each message: it reads every topic of the graph (the monitor and
the recorder, about twenty messages a tick), and each wake-up cost more than taking the message (docs/graph.md,
"Lockstep").  Nothing waits for it: the simulator keeps at most :data:`moose_ros.lockstep.MONITOR_LAG` ticks ahead
of what the monitor has read, within the depth of its readers, and the monitor judges simulated time."""
LOCKSTEP_MIN_RATE = 0.05
"""The slowest lockstep run the launcher waits for (simulated seconds per wall-clock second), beyond start-up."""
FINISH_DRAIN = 5.0
"""Seconds the launcher keeps listening for the simulator's ``finished`` status once its process has exited with 0
and the status has not arrived: the simulator sends it before it exits, but on a loaded machine the launcher can see
the exit first (1 of 40 rclpy launches, four at once on 2 cores, was judged ``incomplete``, exit 3, although the
simulator had finished)."""


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
    (``lockstep_nodes``, :mod:`moose_ros.lockstep`) and runs on the ticks, not on a clock, and the ``faults`` (the
    fault plan: which nodes the graph waits for at each tick).
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
    given["monitored"] = True  # this launcher's monitor reads the graph: nothing of the first tick passes it by
    if lockstep:
        given["lockstep_nodes"] = list(nodes)
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
        if lockstep and faults:  # the simulator's marker names who is waited for; a node that does not read it
            overrides["faults"] = [str(f) for f in faults]  # works it out from the plan (moose_ros.lockstep)
        merged = _file_params(params_file, name)
        for key, value in overrides.items():
            set_dotted(merged, key, value)
        config, own = node_parameters(name, merged)  # refuses what the node would refuse
        if name == "vehicle_simulator" and lockstep:
            sensor_transit(config, own.vehicle_bus, True)  # the CAN graph's hop is a tick: no shorter sensor delay
            check_stalls(faults, config.motion_period)  # a stalled node's backlog fits the lockstep queues
        out[name] = overrides
    return out


def check_domain(node: NodeBase, wait: float = DOMAIN_CHECK) -> None:
    """Refuse to start a graph in a DDS domain where nodes of another moose graph run (a run whose launcher
    was killed, or another launch): their messages would mix with this run's.  Listens ``wait`` seconds
    to ``ros_discovery_info`` through ``node``; a :class:`ParamError` names the nodes found."""
    deadline = time.monotonic() + wait
    found: list[tuple[str, str]] = []
    while time.monotonic() < deadline:
        node.spin_once(0.05)
        found = [n for n in node.node_names() if n[1] in NODES or n[1] == MONITOR]
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
    out: TextIO = sys.stdout,
    bag: Optional[Union[str, Path]] = None,
    foxglove: Optional[tuple[str, int]] = None,
    runtime: Union[None, str, Mapping[str, str]] = None,
    lockstep: bool = False,
) -> dict[str, Any]:
    """Run the graph once and return the summary: the keys of ``moose simulate``'s, plus ``node_exits``,
    ``node_status``, ``incidents``, ``degraded``, ``deadline_misses``, ``stalls``, ``real_time_factor``,
    ``interrupted``, ``faults``, ``diagnostics``, ``odom_samples``, ``final_position_m``, ``final_speed_mps``,
    ``invalid_messages``, ``runtime`` (what each node and the monitor ran on) and ``exit_status``
    (:func:`moose.verdict.exit_status`).

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
    spec = RunSpec(scenario, planner, seed, rate, lockstep, tuple(faults), params_file)
    supervisor = Supervisor(spec, overrides, params, runtime, out)
    supervisor.open(bag, foxglove)
    with supervisor.signals_stop_the_run():
        try:
            supervisor.run(duration)
        finally:
            supervisor.close()
    return supervisor.summary()


@dataclasses.dataclass(frozen=True)
class RunSpec:
    """What one launch runs: the scenario, the planner, the seed, the pace and the faults."""

    scenario: Scenario
    planner: PlannerMode
    seed: int
    rate: float
    """Simulated seconds per wall-clock second (not used in lockstep)."""
    lockstep: bool
    faults: tuple[Fault, ...]
    params_file: Optional[str]


class Supervisor:
    """One run of the graph: owns the node processes, the monitor (:class:`moose_ros.monitor.Monitor`) and its
    DDS node, the fault injector, the bag recorder and the live view, and decides when and why the run ends.

    Its life: the constructor (the monitor and its node), :meth:`open` (the domain check, the recorder, the live
    view), :meth:`run` (start the nodes, watch them until the run ends), :meth:`close` (stop everything, always),
    :meth:`summary`."""

    def __init__(self, spec: RunSpec, overrides: dict[str, dict[str, Any]], params: Mapping[str, Any],
                 runtime: Union[None, str, Mapping[str, str]], out: TextIO) -> None:
        self.spec, self.overrides, self.out = spec, overrides, out
        self.simulated = "vehicle_simulator" in overrides
        self.children = {name: process(runtime.get(name) if isinstance(runtime, Mapping) else runtime)
                         for name in overrides}
        self.runtimes = {name: env["MOOSE_RUNTIME"] for name, (_python, env) in self.children.items()}
        # the monitor: on the nodes' runtime when this interpreter can run it, else (and for a mixed graph) on Cyclone
        self.runtimes[MONITOR] = ("rclpy" if set(self.runtimes.values()) == {"rclpy"} and not rclpy_missing()
                                       else "dds")
        # what the nodes run with: the file, then the values given to every node (timing, friction belief, --set)
        shared = {key: value for key, value in params.items() if "." in key}
        config = spec.scenario.configure(with_overrides(load_config(spec.params_file, reader=None), shared))
        self.monitor = Monitor(spec.scenario, config)
        self.log = self.monitor.log
        self.procs: dict[str, Child] = {}
        self.last_lines: dict[str, list[str]] = {}
        """Each node's last three lines of output (a node that fails to start is reported with them)."""
        self.exits: dict[str, int] = {}
        self.ends: dict[str, str] = {}
        """How each node ended, in words (``finished``, ``stopped``, ``died (…)``, ``failed to start (…)``)."""
        self.silent: set[str] = set()
        """Nodes silent on /diagnostics beyond the deadline (reported once per silence)."""
        self.interrupted: list[str] = []
        """The signals that stopped the run."""
        self.cut_short = ""
        """Why the run ended before it was over (``""``: it was not cut short)."""
        self.lock = threading.Lock()
        self.stop = threading.Event()
        self.injector = FaultInjector(spec.faults, self.procs, spec.rate, self.log, self.say,
                                      tick=self.monitor.config.motion_period if spec.lockstep else None)
        self.recorder: Optional[Recorder] = None
        self.live: Optional[LiveView] = None
        self.forks = self.fork_server()
        self.node = create_node(MONITOR, overrides={"use_sim_time": False}, runtime=self.runtimes[MONITOR])
        """The monitor's node (created last: nothing else here holds a resource that needs closing)."""

    def fork_server(self) -> Optional[ForkServer]:
        """The fork server (:func:`moose_ros.forkserver.shared`) for the nodes on our Cyclone runtime under this
        interpreter (started now if it must be, so that its preload overlaps the domain check); None when there are
        none."""
        forked = [name for name, (python, env) in self.children.items()
                  if python == sys.executable and env["MOOSE_RUNTIME"] == "dds"]
        return shared(self.children[forked[0]][1]) if forked else None

    def open(self, bag: Optional[Union[str, Path]], foxglove: Optional[tuple[str, int]]) -> None:
        """The domain check on the monitor's node (:func:`check_domain`), the recorder of ``bag`` and the live view
        on ``foxglove``: all before any node starts; what was opened is closed again if one of them fails."""
        try:
            check_domain(self.node)
            self.monitor.attach(self.node)
            spec = self.spec
            if spec.lockstep:  # the simulator keeps at most MONITOR_LAG ticks ahead of what the monitor has read
                marker = self.node.publisher(TICK_TYPE, marker_topic(MONITOR), QOS_MARKER)
                self.monitor.acknowledge = lambda t: marker(marker_message(self.node.make, MONITOR, t, []))
            if bag is not None:  # an unusable path stops here; the run's parameters are kept (moose bag replan)
                self.recorder = Recorder(self.node, bag, parameters=RunParameters(
                    self.monitor.config, spec.scenario, spec.planner, spec.seed))
            if foxglove is not None:
                self.live = LiveView(self.node, host=foxglove[0], port=foxglove[1])
                self.out.write(f"[launch] Foxglove live view on {self.live.url}\n")
        except Exception:
            if self.recorder is not None:
                self.recorder.close()
            self.node.shutdown()
            raise

    @contextlib.contextmanager
    def signals_stop_the_run(self) -> Iterator[None]:
        """SIGINT and SIGTERM end the run (it is then cut short) rather than the launcher, while in this block (in
        the main thread only: Python handles signals there)."""
        def on_signal(signum: int, _frame: Any) -> None:
            self.interrupted.append(signal.Signals(signum).name)
            self.stop.set()

        previous = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)} \
            if threading.current_thread() is threading.main_thread() else {}
        try:
            yield
        finally:
            for sig, handler in previous.items():
                signal.signal(sig, handler)

    def say(self, text: str) -> None:
        """A line of the launcher's own on ``out``."""
        with self.lock:
            self.out.write(f"[launch] {text}\n")
            self.out.flush()

    def run(self, duration: Optional[float]) -> None:
        """Start the nodes and watch them until the run ends: the simulator finished or ended, a node failed to
        start, a signal, or the time limit (``duration`` seconds of wall-clock time, else :meth:`time_allowed`)."""
        self.start_nodes()
        start = time.monotonic()
        limit = start + (duration if duration is not None else self.time_allowed())
        while not self.stop.is_set() and time.monotonic() < limit:
            self.listen()
            t_sim = self.monitor.sim_time
            t_fault = t_sim if self.simulated else time.monotonic() - start
            if t_fault is not None:
                self.injector.poll(t_fault)
            self.reap(t_sim)
            if self.ended_by_nodes():
                break
            self.watch_heartbeats()
            if self.monitor.finished:
                limit = min(limit, time.monotonic() + 15.0)  # the simulator is closing down
        else:
            if self.stop.is_set():
                self.cut_short = f"{self.interrupted[0] if self.interrupted else 'a signal'} to the launcher"
            elif self.simulated and not self.monitor.finished:
                self.cut_short = "the time limit of the run was reached"
        for _ in range(10):  # let the last messages arrive
            self.node.spin_once(0.02)

    def listen(self) -> None:
        """Run the node's callbacks for a while: in lockstep, :data:`LOCKSTEP_POLL` seconds, then what arrived in
        them; in real time as each message arrives (the monitor's deadlines and the recorder's stamps are the wall
        clock's), for 0.05 s."""
        if self.spec.lockstep:
            self.stop.wait(LOCKSTEP_POLL)
            self.node.spin_some()
        else:
            self.node.spin_once(0.05)

    def start_nodes(self) -> None:
        """Every node as ``python -m moose_ros.nodes NAME`` with its parameters, its output streamed: forked by the
        fork server when it can (:meth:`fork_server`), else started by ``exec``."""
        for name, given in self.overrides.items():
            python, env = self.children[name]
            args = [name]
            if self.spec.params_file:
                args += ["--params", self.spec.params_file]
            for key, value in given.items():
                args += ["--param", f"{key}={json.dumps(value)}"]
            proc: Child
            if self.forks is not None and self.forks.serves(python, env):
                proc = self.forks.start(NODES_MODULE, args)
            else:
                proc = spawn([python, "-m", NODES_MODULE, *args], env=env, stdout=subprocess.PIPE,
                             stderr=subprocess.STDOUT, text=True)
            self.procs[name] = proc
            threading.Thread(target=self.stream, args=(name, proc), daemon=True).start()

    def stream(self, name: str, proc: Child) -> None:
        """A node's output, each line prefixed with ``[name]`` (in a thread of its own, to the node's end)."""
        assert proc.stdout is not None
        for line in proc.stdout:
            with self.lock:
                self.out.write(f"[{name}] {line}")
                self.out.flush()
                self.last_lines[name] = (self.last_lines.get(name, []) + [line.rstrip()])[-3:]

    def time_allowed(self) -> float:
        """Wall-clock seconds the run may take.  With the simulator: its run at ``rate`` plus its start-up (it waits
        up to a minute for the nodes); in lockstep, as fast as the graph goes down to :data:`LOCKSTEP_MIN_RATE` (a
        graph that stops going ends itself: lockstep_stuck); without a simulator (the car): the planned run."""
        planned = self.spec.scenario.end_time
        if self.spec.lockstep:
            return planned / LOCKSTEP_MIN_RATE + 60.0 + STUCK_TIMEOUT
        return planned / self.spec.rate + 60.0 if self.simulated else planned

    def reap(self, t_sim: Optional[float]) -> None:
        """Record each node that exited since the last look: how it ended, and an incident unless it finished."""
        for name, proc in self.procs.items():
            code = proc.poll()
            if code is None or name in self.exits:
                continue
            self.exits[name] = code
            if name not in self.log.announced:
                self.ends[name] = f"failed to start ({_status_text(code)})"
                detail = " | ".join(self.last_lines.get(name, [])) or "no output"
                self.log.add(t_sim, name, "failed_to_start", f"exited with {_status_text(code)} before it "
                                                             f"announced itself: {detail}")
            elif name == "vehicle_simulator" and code == 0 and self._heard_finish():
                self.ends[name] = "finished"
            else:
                self.ends[name] = f"died ({_status_text(code)})"
                self.log.add(t_sim, name, "died", f"exited with {_status_text(code)} during the run"
                             + (" (the injected fault)" if name in self.injector.killed else ""))
                self.say(f"node {name} exited with status {code}; the graph keeps running")

    def _heard_finish(self) -> bool:
        """Whether the simulator's ``finished`` status arrived, listening up to :data:`FINISH_DRAIN` for it."""
        deadline = time.monotonic() + FINISH_DRAIN
        while not self.monitor.finished and time.monotonic() < deadline:
            self.node.spin_once(0.05)
        return self.monitor.finished

    def ended_by_nodes(self) -> bool:
        """Whether the nodes ended the run: one failed to start, or the simulator ended (cut short unless it had
        finished)."""
        failed = [n for n, e in self.ends.items() if e.startswith("failed to start")]
        if failed:
            self.cut_short = f"{', '.join(failed)} failed to start"
            return True
        if "vehicle_simulator" in self.exits:
            if not self.monitor.finished:
                self.cut_short = "the simulator ended before the run did"
            return True
        return False

    def watch_heartbeats(self) -> None:
        """A running node silent on /diagnostics for longer than the topic's deadline (on its own clock: simulated
        time for the nodes on ``use_sim_time`` or in lockstep, the wall clock for the others) is a ``stalled``
        incident, once per silence.  The simulator is not watched once it has finished: it is going away (it waits
        up to ``FINAL_DELIVERY`` for its readers' acknowledgements, then tears down), and the launcher awaits its
        exit.  Nor is a node the launcher has killed (an injected ``kill``): it is silent because it is dead, and its
        end is the incident ``died`` whenever its exit is heard; when that is, is the machine's load, not the run's
        (ci49: a killed ``weight_fbl`` was ``stalled`` too, three simulated seconds after its last status, when the
        fork server's report of its exit came that late)."""
        deadline = DIAGNOSTICS.deadline
        assert deadline is not None
        now_wall, now_sim = time.monotonic(), self.monitor.sim_time
        for name in self.procs:
            if name in self.exits or name in self.injector.killed or name not in self.monitor.heard or (
                    name == "vehicle_simulator" and self.monitor.finished):
                continue
            wall, sim = self.monitor.heard[name]
            on_sim = bool(self.overrides[name].get("use_sim_time") or self.overrides[name].get("lockstep_nodes"))
            if on_sim and (now_sim is None or sim is None):
                continue
            quiet = (now_sim - sim) if on_sim else (now_wall - wall)
            if quiet > deadline and name not in self.silent:
                self.silent.add(name)
                self.log.add(now_sim, name, "stalled", f"silent on /diagnostics for {quiet:.1f} s "
                                                       f"({'simulated' if on_sim else 'wall-clock'} time)")
            elif quiet <= deadline:
                self.silent.discard(name)

    def close(self) -> None:
        """End the run: stalled nodes continue, every node stops (:meth:`stop_children`), the live view, the
        monitor's node and the recorder close."""
        self.injector.release()
        self.stop_children()
        if self.live is not None:
            self.live.close()
        self.node.shutdown()
        if self.recorder is not None:
            self.recorder.close()

    def stop_children(self) -> None:
        """SIGCONT and SIGTERM to every running node, SIGKILL after :data:`STOP_GRACE`; the monitor keeps listening
        meanwhile (the nodes' final statuses carry their final counters)."""
        running = [name for name, proc in self.procs.items() if proc.poll() is None and name not in self.exits]
        for name in running:
            for sig in (signal.SIGCONT, signal.SIGTERM):
                try:
                    self.procs[name].send_signal(sig)
                except ProcessLookupError:
                    pass
        deadline = time.monotonic() + STOP_GRACE
        while time.monotonic() < deadline and any(self.procs[n].poll() is None for n in running):
            try:
                self.node.spin_once(0.05)
            except Exception:  # noqa: BLE001 - the monitor may be gone on an error path; the children still stop
                time.sleep(0.05)
        hung = [name for name in running if self.procs[name].poll() is None]
        for name in hung:  # where it hangs, in the run's log (moose_ros.nodes.STACK_DUMP), then SIGKILL
            self.procs[name].send_signal(STACK_DUMP)
        if hung:
            time.sleep(STACK_DUMP_WAIT)
        for name, proc in self.procs.items():
            code = proc.poll()
            if code is None:
                proc.kill()
                code = proc.wait()
                if name in running:
                    self.ends[name] = f"did not stop within {STOP_GRACE:g} s of SIGTERM: killed"
                    self.log.add(self.monitor.sim_time, name, "died", self.ends[name])
            self.exits.setdefault(name, code)
            if name in running and name not in self.ends:
                if code == 0:
                    self.ends[name] = "stopped"
                else:
                    self.ends[name] = f"did not stop cleanly ({_status_text(code)})"
                    self.log.add(self.monitor.sim_time, name, "died", self.ends[name])

    def summary(self) -> dict[str, Any]:
        """The run's summary (see :func:`launch`), after the incidents only the end tells are recorded: the run
        cut short, the deadline misses the nodes counted, a rate not held."""
        self.record_end_incidents()
        spec, monitor = self.spec, self.monitor
        summary = summarize(monitor.result(spec.planner, spec.seed))
        if self.cut_short:
            if summary["outcome"] in ("clear", "stopped_short"):  # never a success from a run cut short
                summary["outcome"], summary["complete"] = "incomplete", False
            summary["reason"] = f"the run was cut short ({self.cut_short}); {summary['reason']}"
        last = monitor.odom[-1] if monitor.odom else None
        counters = sorted(self.log.counters.items())
        summary.update(
            node_exits=self.exits,
            node_status=self.ends,
            diagnostics={k: {"level": v[0], "message": v[1]} for k, v in monitor.diagnostics.items()},
            odom_samples=len(monitor.odom),
            final_position_m=None if last is None else [last[1], last[2]],
            final_speed_mps=None if last is None else math.hypot(last[4], last[5]),
            incidents=[i.as_dict() for i in self.log.incidents],
            degraded=self.log.degraded,
            deadline_misses={n: int(c.get("deadline_misses", 0)) for n, c in counters},
            stalls={n: int(c.get("stalls", 0)) for n, c in counters},
            real_time_factor={"requested": None if spec.lockstep else spec.rate,
                              "achieved": monitor.real_time_factor()},
            interrupted=self.interrupted[0] if self.interrupted else None,
            faults=[str(f) for f in spec.faults],
            invalid_messages=monitor.invalid,
        )
        summary["exit_status"] = exit_status(summary["outcome"], summary["degraded"], summary["interrupted"])
        summary["lockstep"] = spec.lockstep
        summary["runtime"] = self.runtimes
        summary["bag_error"] = self.recorder.error if self.recorder is not None else None  # the recording, not the run
        return summary

    def record_end_incidents(self) -> None:
        """The incidents of the whole run: cut short, deadline misses (from the nodes' final counters), the rate
        not held (below :data:`moose_ros.incidents.RATE_TOLERANCE` of the requested one; not in lockstep)."""
        if self.cut_short:
            self.log.add(self.monitor.sim_time, "launch", "cut_short", self.cut_short)
        for name, counters in sorted(self.log.counters.items()):
            misses = int(counters.get("deadline_misses", 0))
            if misses:
                self.log.add(None, name, "deadline_missed", f"{misses} deadline misses (longest executor gap "
                                                            f"{counters.get('longest_gap_ms', 0):.0f} ms)")
        achieved = self.monitor.real_time_factor()
        rate = self.spec.rate
        if not self.spec.lockstep and achieved is not None and achieved < RATE_TOLERANCE * rate:
            self.log.add(None, "vehicle_simulator", "rate_not_held",
                         f"--rate {rate:g} not held: achieved {achieved:.2f} (below {RATE_TOLERANCE:g} × requested)")


def _status_text(code: int) -> str:
    if code < 0:
        try:
            return f"signal {signal.Signals(-code).name}"
        except ValueError:
            return f"signal {-code}"
    return f"exit status {code}"
