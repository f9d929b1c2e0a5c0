"""The lockstep graph (``moose launch --lockstep``): every node computes each simulated tick from exactly the
messages of that tick, so the graph computes what ``moose simulate`` computes, whatever the machine's speed.

**Protocol.**  A node in lockstep publishes, after its outputs of tick k, a marker ``moose_msgs/msg/Tick`` on
``/lockstep/<node>`` (:func:`marker_topic`): the tick's stamp and the topic of every message it published for
that tick, in publication order.  The simulator's marker of tick k (the *root*) also names the nodes the graph
waits for at tick k (its fault plan: a node killed at simulated t drops out from t on, one stalled for d from t to
t + d).

* The simulator publishes the sensor samples of tick k (those the sensor delay makes due at k), the obstacle
  when it appears, and its marker k; it steps the plant to k + 1 only when every expected node has reported
  tick k (:class:`TickJoin`), with the commands of tick k through the command delay
  (:class:`moose.timing.CommandHold`).  It reads the markers of the nodes that imply all others
  (:func:`root_reads`: the last nodes of the tick for each set its fault plan can leave out, and the commands'
  publisher), not all of them: each marker is a datagram per reader.
* Every other node handles tick k when the markers of its upstream nodes (:func:`waits`: the publishers of its
  inputs; of tick k for those before it in :data:`PIPELINE`, of tick k − 1 for the feedback from those after it,
  the blend the MPC warm-starts from, the commands the simulator applies) have arrived, with every message they
  announce: the root's marker k where it reads what the root publishes (:func:`reads_root`); a node that does not
  (the planners, ``weight_fbl``) knows from the fault plan which nodes the graph waits for at k
  (:func:`expected_at`, the ``faults`` every lockstep node is given), as the root's marker says it.  It then hands
  those messages to its callbacks in a fixed order (feedback first, then each upstream node in pipeline order, each
  in its publication order), runs its tick (the planning instants due, the estimate, the reference, the command),
  supervises its inputs on the tick's simulated time, and publishes its marker.
* The delays are the timing model's, where the car has them: the sensor delay in the simulator
  (:class:`moose.timing.DelayLine`), the planning delay in ``weight_fbl``'s planning step, the command delay in
  the simulator (or the ECU emulator); no delay is left to the scheduler.

The launcher's monitor (:data:`MONITOR`, with the node parameter ``monitored``) is not in the pipeline: it
judges and records the run and computes nothing the graph reads.  It acknowledges the odometry it has read on its
own marker, and the simulator keeps at most :data:`MONITOR_LAG` ticks ahead of it, so that a slow launcher slows
the graph rather than losing what it must judge and record.

Markers and the data a lockstep node reads are reliable with a keep-last depth of :data:`DEPTH`; the markers are
transient local (a late joiner still sees them).  A node the root marker does not expect at a tick (a fault,
:func:`left_out`: killed, or stalled) runs no tick then, and who reads it does not wait for it; what it would have
read waits in its queues, and when the graph expects it again (a stall's end) it gets what its subscriptions' depths
on the car keep (:meth:`TickJoin.take`).  A graph that
stops reporting (a node that never publishes its marker) is not waited for forever: the simulator gives up after
:data:`STUCK_TIMEOUT` seconds of wall-clock time with the ``lockstep_stuck`` error and ends the run.
"""
from __future__ import annotations

from collections import deque
from typing import Any, Callable, Collection, Optional

from .graph import (
    ACTUATOR_COMMAND,
    BLEND,
    CLOCK,
    DIAGNOSTICS,
    ODOM,
    PLAN_MPC,
    STEERING,
    THREAT,
    Topic,
    subscribes,
)
from .runtime.qos import Qos

TICK_TYPE = "moose_msgs/msg/Tick"
ROOT = "vehicle_simulator"
"""The node that owns simulated time and whose marker opens every tick."""
PIPELINE: tuple[str, ...] = ("vehicle_simulator", "observer", "obstacle_detector", "mpc_planner", "msf_planner",
                             "weight_fbl", "motion_controller", "can_bridge")
"""The order in which a tick flows through the graph (paper Fig. 3): a node reads tick k of the nodes before it
and tick k − 1 of the nodes after it.  The CAN bridge comes last: it forwards the tick's commands to the bus, and
the sensor samples it decodes reach the observer and the motion controller one tick later (the bus hop)."""
BUS = "can"
"""The pseudo-topic of the CAN bus in a marker: one entry per frame the node sent on the bus for the tick."""
BUS_PARTIES: tuple[str, ...] = ("vehicle_simulator", "can_bridge")
"""Who sends frames to whom: the vehicle-ECU emulator (the simulator) and the bridge."""
BUS_TOPICS: dict[str, tuple[str, ...]] = {"vehicle_simulator": (ACTUATOR_COMMAND.name,)}
"""What a bus party reads as frames instead of as a topic when the graph has the bridge."""
DEPTH = 100
"""Keep-last depth of the markers and of every input a lockstep node reads (a tick carries a few messages)."""
QOS_MARKER = Qos(reliable=True, depth=DEPTH, transient_local=True)
QOS_DATA = Qos(reliable=True, depth=DEPTH, transient_local=True)
"""What a lockstep node's data publishers offer and its subscriptions request: nothing may be lost, since a
node waits for every message a marker announces.  Transient local: a writer sees its reader matched before the
reader has matched the writer, and a volatile reader that matches late starts after what was already sent; the
lockstep replay into an observer (tests/test_bags.py) once waited 60 s for a tick-0 sample lost so."""
MATCH_RETRY = 0.02
"""Wall-clock period (s) at which a lockstep node retries a tick it could not handle yet (discovery at start)."""
BUS_POLL = 0.001
"""Wall-clock period (s) at which a lockstep node on the CAN bus reads its frames when the bus has no file descriptor
to wait on (python-can's ``virtual`` bus); otherwise the frames wake it (:meth:`moose_ros.runtime.base.NodeBase.watch`:
polling every millisecond cost the CAN graph's two bus parties CPU time for every wall-clock millisecond of a run)."""
MONITORED: tuple[str, ...] = tuple(t.name for t in (ODOM, STEERING, PLAN_MPC, BLEND, THREAT, DIAGNOSTICS))
"""What the launcher's monitor reads (:meth:`moose_ros.monitor.Monitor.attach`): with ``monitored`` a lockstep
publisher of these waits for its reader as for the graph's, so the summary misses nothing of tick 0."""
MONITOR = "moose_monitor"
"""The launcher's monitor node (:mod:`moose_ros.monitor`), a reader of the graph outside its pipeline."""
MONITOR_LAG = DEPTH // 2
"""Ticks the launcher's monitor may fall behind the simulator (with ``monitored``): the simulator steps past
tick k only when the monitor has acknowledged tick k − MONITOR_LAG on its marker.  The monitor, and the recorder in
its process, read with a keep-last depth of :data:`DEPTH`; a reader that falls further behind than that loses
samples (a gap in the run's odometry: an incomplete verdict, a bag with holes), which a starved launcher did while
the graph ran on.  Half the depth leaves room for the acknowledgements' granularity."""
MONITOR_ACK_EVERY = 10
"""The monitor acknowledges every this many ticks of odometry (its marker is the last tick it has read)."""
STUCK_TIMEOUT = 90.0
"""Wall-clock seconds the simulator waits for one tick before it ends the run with ``lockstep_stuck``."""


def marker_topic(node: str) -> str:
    """``/lockstep/<node>``."""
    return f"/lockstep/{node}"


def data_topics(node: str) -> list[Topic]:
    """The inputs of ``node`` that carry a tick's data (not the clock, not health)."""
    return [t for t in subscribes(node) if t is not CLOCK and t is not DIAGNOSTICS]


def reads_root(node: str, nodes: Collection[str]) -> bool:
    """Whether ``node`` waits for the root's marker: it reads what the root publishes (the samples, the obstacle;
    the bus's frames), or an input no other node of ``nodes`` publishes (the bag player, as the root, announces what
    it plays).  One datagram less per tick for each node that does not."""
    if node in BUS_PARTIES:
        return True
    return any(ROOT in t.publishers or not [p for p in t.publishers if p in nodes and p != ROOT]
               for t in data_topics(node))


def waits(node: str, nodes: Collection[str], faulted: Optional[Collection[str]] = None) -> dict[str, int]:
    """Whose markers ``node`` waits for before it handles tick k, and the lag of each (the marker of tick k − lag),
    in the order their messages are handed over: feedback (lag 1) first, then pipeline order.  A node waits for the
    root's tick k where :func:`reads_root`.  The root steps past k once the nodes of :func:`root_reads` (``faulted``:
    the nodes of its fault plan) have reported k; with ``faulted`` ``None`` (the bag player), once every node has."""
    if node == ROOT:
        chosen = root_reads(nodes, faulted) if faulted is not None else set(nodes)
        return {n: 0 for n in PIPELINE if n in nodes and n in chosen and n != ROOT}
    position = PIPELINE.index(node)
    out: dict[str, int] = {ROOT: 0} if reads_root(node, nodes) else {}
    for topic in data_topics(node):
        for publisher in topic.publishers:
            if publisher in nodes and publisher != node:
                out[publisher] = 0 if PIPELINE.index(publisher) < position else 1
    return dict(sorted(out.items(), key=lambda item: (-item[1], PIPELINE.index(item[0]))))


def sinks(nodes: Collection[str], expected: Collection[str]) -> frozenset[str]:
    """The nodes of ``expected`` but the root whose tick k no other node of ``expected`` waits for: once they have
    reported k, every node of ``expected`` has (a node waits for tick k of each expected publisher before it in
    :data:`PIPELINE`, so every other node has a chain of such waits to one of them)."""
    present = [n for n in PIPELINE if n in nodes and n in expected and n != ROOT]
    return frozenset(n for n in present if not any(m != n and waits(m, nodes).get(n) == 0 for m in present))


def root_reads(nodes: Collection[str], faulted: Collection[str] = ()) -> frozenset[str]:
    """The nodes whose markers the root reads: the publishers of its inputs (the commands; on the CAN bus the
    bridge, whose marker counts the command frames) and the :func:`sinks` of every set of nodes the fault plan can
    leave out at once (``faulted``: the nodes with a fault).  Every marker the root does not read is one datagram
    less per tick: in the full graph one marker instead of six (9 % of the lockstep full graph's CPU time,
    docs/graph.md "Lockstep")."""
    bus = "can_bridge" in nodes
    out = {p for t in data_topics(ROOT) if not (bus and t.name in BUS_TOPICS[ROOT])
           for p in t.publishers if p in nodes and p != ROOT} | ({"can_bridge"} if bus else set())
    optional = sorted(set(faulted) & set(nodes) - {ROOT})
    for mask in range(1 << len(optional)):
        expected = set(nodes) - {n for i, n in enumerate(optional) if mask >> i & 1}
        out |= sinks(nodes, expected)
    return frozenset(out)


def readers(topic: Topic, nodes: Collection[str]) -> int:
    """How many nodes of the graph read ``topic`` (on the CAN bus the simulator reads the commands as frames)."""
    bus = "can_bridge" in nodes
    return sum(1 for n in topic.subscribers if n in nodes and not (bus and n in BUS_PARTIES and topic.name in
                                                                     BUS_TOPICS.get(n, ())))


def listeners(node: str, nodes: Collection[str]) -> int:
    """How many nodes of the graph read ``node``'s marker whatever the fault plan (the root reads more of them when
    its plan leaves nodes out, :func:`root_reads`; markers are transient local, so a reader matched after a marker
    went out still gets it)."""
    return sum(1 for other in nodes if other != node and node in waits(other, nodes, () if other == ROOT else None))


def tick_of(t: float, period: float) -> int:
    """The tick index of simulated time ``t``."""
    return int(round(t / period))


def expected_at(nodes: Collection[str], faults: Collection[Any], k: int, period: float) -> frozenset[str]:
    """The nodes the graph waits for at tick ``k`` under the fault plan ``faults`` (:func:`left_out`): what the
    root's marker k says, and what a node that does not read it (:func:`reads_root`) works out itself."""
    return frozenset(n for n in nodes if not any(left_out(f, k, period) for f in faults if f.node == n))


def left_out(fault: Any, k: int, period: float) -> bool:
    """Whether the graph does without ``fault``'s node (a :class:`moose_ros.faults.Fault`) at tick ``k``: a killed
    node from the fault's tick on, a stalled one from it until the tick its stall ends (exclusive: it runs that tick
    again, with its backlog); the root never (a stalled simulator stops simulated time itself)."""
    if fault.node == ROOT or k < tick_of(fault.at, period):
        return False
    return fault.action == "kill" or k < tick_of(fault.at + fault.duration, period)


class TickJoin:
    """Which tick a lockstep node may handle next, and the messages it hands over for it (see the module
    docstring).  Pure bookkeeping, no middleware: the node feeds it every input message (:meth:`message`) and
    every marker (:meth:`marker`) as they arrive, and :meth:`take` returns the next complete tick.  ``faults``:
    the fault plan (:class:`moose_ros.faults.Fault`) and ``period`` the tick's: the root's say whose markers it reads
    (:func:`waits`; ``None``: every node's, the bag player), and a node that does not read the root's marker knows
    from them which nodes the graph waits for at each tick (:func:`expected_at`)."""

    def __init__(self, node: str, nodes: Collection[str], topics: Collection[str] = (),
                 faults: Optional[Collection[Any]] = None, period: float = 0.0) -> None:
        self.node = node
        self.waits = waits(node, nodes, None if faults is None else [f.node for f in faults])
        self.nodes = tuple(nodes)
        self.faults = tuple(faults or ())
        self.period = period
        self.planned = node != ROOT and ROOT not in self.waits
        """No root marker: the nodes expected at each tick come from the fault plan."""
        self.publishes: dict[str, list[str]] = {}
        """Upstream node → the topics of it this node reads."""
        self.queues: dict[str, deque[Any]] = {}
        """The topics this node reads (:meth:`add`) → what arrived and is not handed over yet."""
        for name in topics:
            self.add(name)
        self.markers: dict[str, dict[int, tuple[str, ...]]] = {n: {} for n in self.waits}
        self.expected: dict[int, frozenset[str]] = {}
        """Tick → the nodes the graph waits for (the root's markers; the simulator's own plan)."""
        self.next = 0
        """The tick to handle next."""
        self.backlog: dict[str, int] = {}
        """Topic → the messages announced for the ticks this node was left out of (stalled): they wait in its
        queues until it runs again, and only the newest :meth:`depth` of each are handed over then."""

    @property
    def topics(self) -> frozenset[str]:
        """The topics this node reads."""
        return frozenset(self.queues)

    def add(self, topic: str) -> None:
        """This node reads ``topic`` (a topic of the graph, or :data:`BUS`: the frames of the other bus party)."""
        from .graph import TOPICS

        if topic in self.queues:
            return
        self.queues[topic] = deque()
        publishers = ([n for n in BUS_PARTIES if n != self.node] if topic == BUS
                      else list(TOPICS[topic].publishers) if topic in TOPICS else [])
        for publisher in publishers:
            if publisher in self.waits:
                self.publishes.setdefault(publisher, []).append(topic)

    def message(self, topic: str, item: Any) -> None:
        """A message on ``topic`` (an input of this node) arrived."""
        self.queues[topic].append(item)

    def marker(self, node: str, tick: int, topics: tuple[str, ...], expected: Optional[Collection[str]]) -> None:
        """The marker of ``node`` for ``tick`` arrived (``expected``: the root's, else ``None``)."""
        if expected is not None:
            self.expected[tick] = frozenset(expected)
        if node in self.markers and tick >= self.next - 1:
            self.markers[node][tick] = topics

    def depth(self, topic: str) -> Optional[int]:
        """How many messages of ``topic`` this node's subscription keeps while the node does not run (its keep-last
        depth on the car, :attr:`moose_ros.graph.Topic.subscription_qos`); ``None`` for the bus, whose frames wait in
        the socket's receive buffer."""
        from .graph import TOPICS

        return TOPICS[topic].subscription_qos.depth if topic in TOPICS else None

    def take(self) -> Optional[tuple[int, list[tuple[str, Any]]]]:
        """The next tick this node runs and its messages in hand-over order, or ``None`` while something is missing.

        A tick whose root marker leaves this node out (a fault: killed, or stalled until the graph expects it
        again) is not run: a stopped process does nothing.  What was announced for it stays queued, and at the
        tick the node runs again it gets that backlog first, cut to the newest :meth:`depth` messages of each
        topic (older ones are lost, as from a full reader queue), then the tick's own messages."""
        while True:
            k = self.next
            expected = self._expected(k)
            if expected is None:
                return None
            order = self._announced(k, expected)
            if order is None:
                return None
            if self.node != ROOT and self.node not in expected:  # stopped at k: its inputs pile up
                for topic in order:
                    self.backlog[topic] = self.backlog.get(topic, 0) + 1
                self._done(k)
                continue
            need = dict(self.backlog)
            for topic in order:
                need[topic] = need.get(topic, 0) + 1
            if any(len(self.queues[topic]) < n for topic, n in need.items()):
                return None
            items: list[tuple[str, Any]] = []
            for topic, n in self.backlog.items():
                depth = self.depth(topic)
                kept = n if depth is None else min(n, depth)
                for i in range(n):
                    item = self.queues[topic].popleft()
                    if i >= n - kept:
                        items.append((topic, item))
            self.backlog = {}
            items.extend((topic, self.queues[topic].popleft()) for topic in order)
            self._done(k)
            return k, items

    def _announced(self, k: int, expected: frozenset[str]) -> Optional[list[str]]:
        """The topics this node reads among what its upstream nodes announced for tick ``k`` (each of them at its
        lag), one entry per message in hand-over order; ``None`` while a marker is missing.  A node the graph did not
        expect at the marker's tick ran no tick (faulted) and is not waited for."""
        order: list[str] = []
        for node, lag in self.waits.items():
            tick = k - lag
            if tick < 0 or (node != ROOT and node not in (self._expected(tick) or expected)):
                continue
            topics = self.markers[node].get(tick)
            if topics is None:
                return None
            order.extend(topic for topic in topics if topic in self.queues)
        return order

    def _expected(self, k: int) -> Optional[frozenset[str]]:
        """The nodes the graph waits for at tick ``k``: from the plan, or the root's marker (``None``: not in yet).
        The plan's answer is kept with the markers' (:attr:`expected`, forgotten with them): :meth:`take` asks a few
        times per message (a planner, ``weight_fbl``: about 25 times per tick), always the same of a tick."""
        if self.planned and k not in self.expected:
            self.expected[k] = expected_at(self.nodes, self.faults, k, self.period)
        return self.expected.get(k)

    def _done(self, k: int) -> None:
        """Tick ``k`` is handled (or passed by, stopped): forget its markers; the next is k + 1."""
        for node, lag in self.waits.items():
            self.markers[node].pop(k - lag, None)
        self.expected = {tick: nodes for tick, nodes in self.expected.items() if tick >= k - 1}
        self.next = k + 1


def marker_message(make: Callable[..., Any], node: str, t: float, topics: list[str],
                   expected: Collection[str] = ()) -> Any:
    """The ``Tick`` message of ``node`` for the tick at simulated time ``t``."""
    import math

    sec = int(math.floor(t))
    stamp = make("builtin_interfaces/msg/Time", sec=sec, nanosec=int(round((t - sec) * 1e9)) % 1_000_000_000)
    return make(TICK_TYPE, stamp=stamp, node=node, topics=list(topics), expected=sorted(expected))


def marker_time(msg: Any) -> float:
    """The simulated time of a ``Tick`` message."""
    return float(msg.stamp.sec) + 1e-9 * float(msg.stamp.nanosec)


STALL_TICKS_MAX = DEPTH - 10
"""The longest stall of a node in lockstep, in ticks: while it is stopped, what the graph sends it waits in the
publishers' keep-last histories of :data:`DEPTH` (one marker of each node, and up to one message of each topic, per
tick), and what they dropped it could never be handed over.  Ten ticks of margin for what is in flight at SIGSTOP."""


def check_stalls(faults: Collection[Any], period: float) -> None:
    """A :class:`moose.params.ParamError` for a stall of a node other than the simulator longer than
    :data:`STALL_TICKS_MAX` ticks of ``period`` (lockstep; :class:`moose_ros.faults.Fault`)."""
    for fault in faults:
        if fault.action == "stall" and fault.node != ROOT and tick_of(fault.duration, period) > STALL_TICKS_MAX:
            from moose.params import ParamError

            raise ParamError(f"--fault {str(fault)!r} is invalid in lockstep: a stall lasts at most "
                             f"{STALL_TICKS_MAX * period:g} s ({STALL_TICKS_MAX} ticks: the graph's queues keep "
                             f"{DEPTH}); run it at real time")


def sensor_transit(config: Any, vehicle_bus: str, lockstep: bool) -> float:
    """The sensor delay the simulator applies itself (the rest is the transport's): all of ``timing.sensor_delay_s``
    on topics; none on the CAN bus in real time (the bus is the hop); in lockstep on the CAN bus all but the one tick
    by which the stack reads the bridge's samples (:data:`PIPELINE`).  A :class:`moose.params.ParamError` when the
    delay is shorter than that tick."""
    delay = config.timing.sensor_delay_s
    if vehicle_bus != "can":
        return float(delay)
    if not lockstep:
        return 0.0
    period = config.motion_period
    if delay < period - 1e-9:
        from moose.params import ParamError

        raise ParamError(f"timing.sensor_delay_s = {delay!r} is invalid for the CAN graph in lockstep: its bus hop "
                         f"is one motion tick ({period:g} s), the least sensor delay it can have")
    return float(delay - period)
