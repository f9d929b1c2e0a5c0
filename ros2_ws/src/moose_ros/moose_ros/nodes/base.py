"""What every node shares: the runtime node, its typed parameters, supervised inputs and the diagnostics heartbeat.

**Supervision.**  Every node watches the freshness of its inputs (:class:`InputWatch`): an input whose last
sample arrived longer ago than its topic's deadline (:attr:`moose_ros.graph.Topic.deadline`, derived from the
designed rate) is *stale*; an input never received is stale :data:`~moose_ros.graph.STARTUP_GRACE` after the
node's clock started.  The node's :meth:`GraphNode.supervise` runs every
:data:`~moose_ros.graph.SUPERVISION_PERIOD` on the node's clock (simulated time with ``use_sim_time``, else
the monotonic clock), hands the stale set to :meth:`GraphNode.on_inputs` (each node decides what a stale
input means for its job) and measures the node's own executor: a gap between two supervision cycles longer
than :data:`~moose_ros.graph.CYCLE_DEADLINE` is a deadline miss, longer than
:data:`~moose_ros.graph.STALL_TIME` a stall (SIGSTOP, a hung callback, a starved CPU), both counted.

**Validation.**  :meth:`GraphNode.subscribe` is the only way a node subscribes: each message is converted to
its core record by :data:`moose_ros.convert.RECORDS`, which validates it.  An invalid message never reaches the
node's code and never raises, and does not count as an arrival for supervision: it is dropped, counted per
topic (``invalid TOPIC`` in the status values), and an ``invalid:TOPIC`` WARN problem (logged when it
starts) stands while such messages arrived within the last :data:`INVALID_HOLD`.

**Diagnostics.**  The status on /diagnostics is the node's own (``level``, ``message``, ``values``, set by
its job) combined with its current *problems* (:meth:`GraphNode.problem`): the highest level wins, the
messages are joined, and ``values`` carries ``problems`` (the problem keys, e.g. ``stale:/perception/state``,
``minimum_risk``), each problem's text under its key, ``deadline_misses``, ``stalls`` and ``longest_gap_ms``.  It is
published once a second (:data:`HEARTBEAT`) and at once whenever its level or its set of problems changes, so a node
that reacts to another's health (the motion controller) hears of an error within one supervision cycle.  Levels:
OK; WARN — degraded, the node still does its job (a planner fell back, a slow cycle); ERROR — the node cannot do its
job, and who depends on it must not rely on its output.
"""
from __future__ import annotations

import time
from collections import Counter
from typing import TYPE_CHECKING, Any, Callable, Iterable, Optional, Sequence

from .. import convert as cv
from ..faults import Fault
from ..graph import (
    CLOCK,
    CYCLE_DEADLINE,
    DIAGNOSTICS,
    STALL_TIME,
    STARTUP_GRACE,
    SUPERVISION_PERIOD,
    TF_STATIC,
    Topic,
    subscribes,
)
from ..lockstep import (
    MATCH_RETRY,
    MONITORED,
    QOS_DATA,
    QOS_MARKER,
    TICK_TYPE,
    TickJoin,
    listeners,
    marker_message,
    marker_time,
    marker_topic,
    readers,
    tick_of,
)
from ..parameters import node_parameters
from ..runtime.base import Handle, NodeBase, Publisher

if TYPE_CHECKING:  # imported in GraphNode.table only: the nodes that build no table do not load it
    from moose.maneuver import MaxSteeringTable

OK, WARN, ERROR = 0, 1, 2
"""diagnostic_msgs/DiagnosticStatus levels."""
INVALID_HOLD = 1.0
HEARTBEAT = 1.0
"""Period (s) of the status on /diagnostics when nothing changes: on the wall clock, and in lockstep also on the
ticks (each simulated second), so that the launcher judges a lockstep node's silence on simulated time."""
"""How long (s) the ``invalid:TOPIC`` problem stands after the last invalid message on TOPIC."""


class InputWatch:
    """When each input last arrived (on the node's clock) and which inputs are past their deadline."""

    def __init__(self, topics: Iterable[Topic], grace: float = STARTUP_GRACE) -> None:
        self.deadlines = {t.name: t.deadline for t in topics if t.deadline is not None}
        """Topic name → deadline (s)."""
        self.grace = grace
        self.last: dict[str, float] = {}
        self.start: Optional[float] = None
        """When supervision started (the node's first supervision cycle)."""

    def seen(self, name: str, now: float) -> None:
        """A sample of ``name`` arrived at ``now``."""
        self.last[name] = now

    def age(self, name: str, now: float) -> Optional[float]:
        """Time since the last sample of ``name`` (s); ``None`` if none arrived yet."""
        last = self.last.get(name)
        return None if last is None else now - last

    def stale(self, now: float, names: Optional[Iterable[str]] = None) -> dict[str, Optional[float]]:
        """The stale inputs among ``names`` (default: all supervised) → their age (``None``: never received,
        and the startup grace is over)."""
        if self.start is None:
            self.start = now
        out: dict[str, Optional[float]] = {}
        for name in self.deadlines if names is None else names:
            age = self.age(name, now)
            if age is None:
                if now - self.start > self.grace:
                    out[name] = None
            elif age > self.deadlines[name] + 1e-9:
                out[name] = age
        return out


def describe_stale(name: str, age: Optional[float], deadline: float) -> str:
    """``/perception/state stale (0.12 s > 0.05 s)`` or ``/perception/state never received``."""
    return f"{name} never received" if age is None else f"{name} stale ({age:.2f} s > {deadline:g} s)"


class GraphNode:
    """Runtime node ``rt``, the core's configuration and the node's own parameters (both validated:
    :func:`moose_ros.parameters.node_parameters`), supervised inputs and the diagnostics heartbeat (see the
    module docstring)."""

    name = "node"

    def __init__(self, rt: NodeBase) -> None:
        self.rt = rt
        self.config, self.params = node_parameters(self.name, rt.parameters)
        if hasattr(self.params, "load_scenario"):  # the simulated road: the scenario's μ, when it sets one
            self.config = self.params.load_scenario().configure(self.config)
        # transient local: a late joiner (the simulator waiting for the graph) sees each node's last status
        self._diag = DIAGNOSTICS.publisher(rt)
        self._writers: dict[str, Publisher] = {DIAGNOSTICS.name: self._diag}
        """This node's publishers by topic (:meth:`deliver`)."""
        self.level, self.message = OK, "running"
        self.values: dict[str, Any] = {}
        self.problems: dict[str, tuple[int, str]] = {}
        """Current problems: key → (level, text); see :meth:`problem`."""
        # /clock is the runtime's (with simulated time, a silent clock stops every deadline with it); /diagnostics
        # is health, not data (the motion controller supervises it itself)
        self.inputs = InputWatch(t for t in subscribes(self.name) if t not in (CLOCK, DIAGNOSTICS))
        self.deadline_misses = 0
        """Executor cycles later than CYCLE_DEADLINE, plus what the node counts itself (a planning slot over
        budget, a late control cycle)."""
        self.stalls = 0
        self.longest_gap = 0.0
        self._last_cycle: Optional[float] = None
        self._deferred = False
        self._published_level: Optional[int] = None
        self._published_stalls = 0
        self._published_problems: frozenset[str] = frozenset()
        self.invalid: Counter[str] = Counter()
        """Invalid messages dropped, by topic."""
        self._invalid_last: dict[str, tuple[float, str]] = {}
        """Topic → (clock of the last invalid message, its reason)."""
        self.tick_period = self.config.motion_period
        """The motion-control tick (s): the lockstep graph's step."""
        self.tick_time: Optional[float] = None
        """Lockstep: the simulated time of the tick being handled (``None`` in real time and before the first)."""
        self.join: Optional[TickJoin] = None
        self._handlers: dict[str, Callable[[Any], None]] = {}
        self._published: list[str] = []
        self._pubs: list[tuple[Publisher, int]] = []
        nodes = tuple(getattr(self.params, "lockstep_nodes", ()))
        if nodes:  # lockstep (moose_ros.lockstep): supervision runs in each tick, not on a timer
            # the inputs it reads join as the node subscribes; the fault plan says whose markers the simulator reads,
            # and which nodes the graph waits for at each tick to a node that does not read the simulator's marker
            plan = [Fault.parse(text) for text in self.params.faults]
            self.join = TickJoin(self.name, nodes, faults=plan, period=self.tick_period)
            self._marker = rt.publisher(TICK_TYPE, marker_topic(self.name), QOS_MARKER)
            self._pubs.append((self._marker, listeners(self.name, nodes)))
            for upstream in self.join.waits:
                rt.subscription(TICK_TYPE, marker_topic(upstream), self._on_marker, QOS_MARKER)
            # the nodes run on no clock of their own in lockstep (the tick's time is theirs): this wall-clock timer
            # only retries a tick that waited for discovery (nothing of tick 0 goes out before it is matched)
            rt.timer(MATCH_RETRY, self._pump)
        else:
            rt.timer(SUPERVISION_PERIOD, self.supervise)
        rt.timer(HEARTBEAT, self.publish_diagnostics)

    @property
    def lockstep(self) -> bool:
        """Whether this node runs in lockstep (``moose launch --lockstep``)."""
        return self.join is not None

    def inputs_of(self) -> list[Topic]:
        """The data topics this node reads (what a lockstep tick carries)."""
        from ..lockstep import data_topics

        return data_topics(self.name)

    def now(self) -> float:
        """The node's simulated time: the tick being handled in lockstep, else the runtime's ROS time."""
        return self.tick_time if self.tick_time is not None else float(self.rt.now())

    def publisher(self, topic: Topic) -> Callable[[Any], None]:
        """A publisher of ``topic`` on this node; in lockstep each message is announced in the tick's marker, and
        the publisher offers :data:`moose_ros.lockstep.QOS_DATA` (nothing a lockstep reader waits for is lost)."""
        watched = bool(getattr(self.params, "monitored", False)) and topic.name in MONITORED
        if self.join is None:
            pub = self._writers[topic.name] = topic.publisher(self.rt)
            if hasattr(self.params, "wait_for"):  # real time: the simulator starts simulated time once its first
                self._pubs.append((pub, readers(topic, self.params.wait_for) + watched))  # samples reach every reader
            return pub
        pub = self._writers[topic.name] = self.rt.publisher(topic.type, topic.name, QOS_DATA)
        nodes = tuple(getattr(self.params, "lockstep_nodes", ()))
        self._pubs.append((pub, readers(topic, [n for n in nodes if n != self.name]) + watched))
        name = topic.name

        def publish(msg: Any) -> None:
            self._published.append(name)
            pub(msg)

        return publish

    def deliver(self, topics: Sequence[Topic], timeout: float) -> bool:
        """Wait up to ``timeout`` seconds in all until every reliable reader of this node's publishers of ``topics``
        has acknowledged what they sent (:meth:`moose_ros.runtime.base.Publisher.wait_acknowledged`): what a node
        sends before it goes away (a deleted writer takes what its readers have not acknowledged with it).  Whether
        they all have; a reader that was killed never acknowledges, and the wait then ends at ``timeout``."""
        deadline = time.monotonic() + timeout
        return all([self._writers[t.name].wait_acknowledged(max(deadline - time.monotonic(), 0.0))
                    for t in topics if t.name in self._writers])

    def matched(self) -> bool:
        """Every publisher of this node reaches every node of the graph that reads it, and the launcher's monitor
        where it reads the topic (nothing of tick 0 may go to a reader not yet discovered): a lockstep node's, and
        in real time the simulator's (the nodes it waits for)."""
        return all(pub.subscription_count() >= count for pub, count in self._pubs)

    def clock(self) -> float:
        """The node's clock for deadlines (s): the tick's simulated time in lockstep, simulated time with
        ``use_sim_time``, else the monotonic clock (immune to wall-clock steps)."""
        if self.tick_time is not None:
            return self.tick_time
        return self.rt.now() if getattr(self.rt, "use_sim_time", False) else time.monotonic()

    def subscribe(self, topic: Topic, handler: Callable[[Any], None]) -> Handle:
        """Subscribe to ``topic`` with its subscribers' QoS; ``handler`` gets the validated record
        (:data:`moose_ros.convert.RECORDS`), and each valid arrival is noted for :attr:`inputs`.  An invalid
        message never reaches ``handler`` and never raises (see the module docstring)."""
        name, convert = topic.name, cv.RECORDS[topic.name]
        if self.join is not None and topic in self.inputs_of():
            self.join.add(name)

        def on_message(msg: Any) -> None:
            now = self.rt.now()
            clock_known = not (self.rt.use_sim_time and now == 0.0)  # ROS 2: time 0 is "no /clock yet"
            try:
                record = convert(msg, now if clock_known else None)
            except cv.InvalidMessage as exc:
                if self.join is not None and name in self.join.topics:  # announced in a marker: counted there
                    reason = str(exc)
                    self.join.message(name, lambda: self.reject(name, reason))
                    self._pump()
                else:
                    self.reject(name, str(exc))
                return
            if self.join is not None and name in self.join.topics:
                self.join.message(name, lambda: self._arrived(name, handler, record))
                self._pump()
            else:
                self._arrived(name, handler, record)

        if self.join is not None and name in self.join.topics:  # the marker announcing them wakes the node
            return self.rt.subscription(topic.type, name, on_message, QOS_DATA, wake=False)
        return topic.subscription(self.rt, on_message)

    def _arrived(self, name: str, handler: Callable[[Any], None], record: Any) -> None:
        self.inputs.seen(name, self.clock())
        handler(record)

    # -- lockstep (moose_ros.lockstep) -------------------------------------------------------

    def _on_marker(self, msg: Any) -> None:
        assert self.join is not None
        expected = tuple(msg.expected) if msg.node == "vehicle_simulator" else None
        self.join.marker(msg.node, tick_of(marker_time(msg), self.tick_period), tuple(msg.topics), expected)
        self._pump()

    def _pump(self) -> None:
        """Handle every tick that is complete (:meth:`moose_ros.lockstep.TickJoin.take`)."""
        join = self.join
        assert join is not None
        while join.next > 0 or self.matched():
            self.poll()
            step = join.take()
            if step is None:
                return
            k, items = step
            self.tick_time = round(k * self.tick_period, 9)
            for _topic, deliver in items:
                deliver()
            self.on_tick(self.tick_time)
            self.supervise()
            self.publish_marker(k)

    def poll(self) -> None:
        """Lockstep: read what arrives other than as messages (the CAN bridge's bus) into the join.  Default:
        nothing."""

    def announce(self, what: str) -> None:
        """Lockstep: count one more output of the tick on ``what`` (a frame on :data:`moose_ros.lockstep.BUS`); the
        node's publishers count their messages themselves."""
        if self.join is not None:
            self._published.append(what)

    def on_tick(self, t: float) -> None:
        """Lockstep: what the node does at the tick ``t`` once its inputs of the tick are handed over (publish its
        estimate, plan, command …).  Default: nothing."""

    def publish_marker(self, k: int, expected: tuple[str, ...] = ()) -> None:
        """Lockstep: announce that this node has published everything for tick ``k``."""
        topics, self._published = self._published, []
        self._marker(marker_message(self.rt.make, self.name, round(k * self.tick_period, 9), topics, expected))
        if k % round(HEARTBEAT / self.tick_period) == 0:
            self.publish_diagnostics()

    def reject(self, topic: str, reason: str) -> None:
        """Count a dropped message on ``topic`` and say why: the ``invalid:TOPIC`` problem (logged when it starts)."""
        self.invalid[topic] += 1
        now = self.clock()
        self._invalid_last[topic] = (now, reason)
        self.problem(f"invalid:{topic}", WARN, f"dropped {self.invalid[topic]} invalid message(s) on {topic}: {reason}")

    # -- supervision ------------------------------------------------------------------------

    def supervise(self) -> None:
        """One supervision cycle: the node's own executor gap, then the stale inputs to :meth:`on_inputs`."""
        now = self.clock()
        gap = 0.0 if self._last_cycle is None else now - self._last_cycle
        self._last_cycle = now
        self.longest_gap = max(self.longest_gap, gap)
        if gap > STALL_TIME:
            self.stalls += 1
            self.rt.log_warn(f"no executor cycle for {gap:.2f} s (stalled or starved)")
        late = gap > CYCLE_DEADLINE
        if late:
            self.deadline_misses += 1
        if late and not self._deferred:
            # this node was late itself: what waits in its readers has not been taken yet, so its inputs are
            # judged in the next cycle, after the executor has run their callbacks (once: a node late every
            # cycle still judges every other one)
            self._deferred = True
        else:
            self._deferred = False
            self.on_inputs(self.inputs.stale(now), now)
        for topic, (when, _reason) in list(self._invalid_last.items()):
            if now - when > INVALID_HOLD:
                del self._invalid_last[topic]
                self.problem(f"invalid:{topic}", None)
        self._publish_on_change()

    def on_inputs(self, stale: dict[str, Optional[float]], now: float) -> None:
        """React to the stale inputs (name → age, ``None``: never received).  Default: each stale input is a
        WARN problem; nodes that cannot work without an input raise it to ERROR (and act)."""
        self.report_stale(stale, WARN)

    def report_stale(self, stale: dict[str, Optional[float]], level: int,
                     levels: Optional[dict[str, int]] = None, names: Optional[Iterable[str]] = None) -> None:
        """Set a ``stale:TOPIC`` problem for each stale input among ``names`` (default: all supervised), at
        ``levels[TOPIC]`` or ``level``; clear the others."""
        for name in self.inputs.deadlines if names is None else names:
            key, deadline = f"stale:{name}", self.inputs.deadlines[name]
            if name in stale:
                self.problem(key, (levels or {}).get(name, level), describe_stale(name, stale[name], deadline))
            else:
                self.problem(key, None)

    def problem(self, key: str, level: Optional[int], text: str = "") -> None:
        """Set problem ``key`` at ``level`` with ``text``, or clear it (``level=None``)."""
        if level is None:
            if self.problems.pop(key, None) is not None:
                self.rt.log_info(f"recovered: {key}")
            return
        previous = self.problems.get(key)
        self.problems[key] = (level, text)
        if previous is None or previous[0] != level:
            (self.rt.log_error if level >= ERROR else self.rt.log_warn)(text)

    def status(self) -> tuple[int, str, dict[str, Any]]:
        """The combined status: (level, message, values) of the job and the problems."""
        level = max([self.level, *(lv for lv, _ in self.problems.values())])
        texts = [text for _lv, text in sorted(self.problems.values(), key=lambda p: -p[0])]
        message = "; ".join(texts) if texts else self.message
        if texts and self.message not in ("running",):
            message = f"{self.message}; {message}"
        values = dict(self.values)
        values.update(problems=",".join(sorted(self.problems)), deadline_misses=self.deadline_misses,
                      stalls=self.stalls, longest_gap_ms=f"{1e3 * self.longest_gap:.0f}")
        values.update({key: text for key, (_level, text) in self.problems.items()})
        values.update({f"invalid {topic}": count for topic, count in sorted(self.invalid.items())})
        return level, message, values

    def _publish_on_change(self) -> None:
        """Publish now when the level or the set of problems changed, or the node noticed a stall of its own.  (On
        the level alone, a WARN problem that came and went while another WARN stood was never published between
        two heartbeats: weight_fbl's fallback during a 0.6 s stall of the MPC, in lockstep.)"""
        if (self.status()[0] != self._published_level or self.stalls != self._published_stalls
                or frozenset(self.problems) != self._published_problems):
            self.publish_diagnostics()

    # -- life cycle -------------------------------------------------------------------------

    def close(self) -> None:
        """Release what the node holds beyond its runtime entities (a bus, a thread); called once at shutdown."""

    def stamp_time(self) -> float:
        """The time that stamps this node's diagnostics: the node's ROS time (simulated with ``use_sim_time``); in
        lockstep the tick's (0 before the first)."""
        if self.join is not None:
            return self.tick_time or 0.0
        return float(self.rt.now())

    def publish_diagnostics(self) -> None:
        level, message, values = self.status()
        self._published_level, self._published_stalls = level, self.stalls
        self._published_problems = frozenset(self.problems)
        self._diag(cv.diagnostic_to_msg(self.rt, self.stamp_time(), self.name, level, message, values))

    def table(self) -> MaxSteeringTable:
        """The maximum steering table of the vehicle the stack believes in (the planning μ; detector, MSF planner)."""
        from moose.maneuver import MaxSteeringTable

        return MaxSteeringTable.build(self.config.model_vehicle, self.config.maneuver)


def sensor_publishers(node: GraphNode, t0: float) -> dict[type, tuple[Callable[[Any], None],
                                                                      Callable[[Any, Any], Any]]]:
    """Publisher and converter of each sensor sample type: the vehicle's sensor topics.  The sensor frames
    go on /tf_static once, stamped ``t0`` (transient local: late joiners get them)."""
    TF_STATIC.publisher(node.rt)(cv.static_tf(node.rt, t0))
    return {kind: (node.publisher(topic), convert) for kind, (topic, convert) in cv.SENSOR_SAMPLES.items()}
