"""The Cyclone DDS backend: a node with rmw_cyclonedds' wire conventions and a single-threaded executor.

The ROS topic ``/ns/x`` is the DDS topic ``rt/ns/x``, type names are ``pkg::msg::dds_::Type_``, data
is XCDR1 little-endian CDR, the domain comes from ``ROS_DOMAIN_ID`` (default 0) and QoS profiles map
one to one (:class:`~moose_ros.runtime.qos.Qos`).  Discovery follows ``ROS_AUTOMATIC_DISCOVERY_RANGE``
and ``ROS_STATIC_PEERS``, confined to this host by default (:mod:`.discovery`): the process creates its
Cyclone DDS domain with that configuration (then ``CYCLONEDDS_URI``), and every node of the process
shares it.  The executor is a single thread, like rclpy's
SingleThreadedExecutor: ``spin`` blocks on a DDS WaitSet (readers, a guard condition for shutdown)
with a timeout up to the next timer, takes what the readers hold and runs the callbacks in
publication order (source timestamps), then the timers that are due.  Samples stay in the DDS
reader history until the executor takes them, so keep-last depths act as in ROS 2 (a slow callback
sees the newest samples, not a backlog).  With ``use_sim_time`` the clock follows ``/clock`` and
timers fire on simulated time.

Discovery is watched: a remote endpoint on one of our topics with another type, or with QoS that
cannot match ours (best effort offered to a reliable reader, volatile to a transient-local one),
is reported once with ``log_error``: such endpoints never exchange data.

Graph introspection as rmw_cyclonedds does it for ROS 2 Jazzy, so ``ros2 node list``, ``ros2 node
info``, rqt_graph and rclpy's graph API see our nodes and their endpoints:

- the participant's USER_DATA is ``enclave=/;``: rmw implementations only count participants that
  carry an enclave;
- every writer and reader carries ``typehash=RIHS01_<64 hex>;`` in its USER_DATA, the RIHS01 hash of
  its message type (rosbags' ``hash_rihs01``; ``rmw_dds_common::encode_type_hash_for_user_data_qos``);
- the participant publishes ``rmw_dds_common/msg/ParticipantEntitiesInfo`` on the DDS topic
  ``ros_discovery_info`` (no ``rt/`` prefix: ``avoid_ros_namespace_conventions``), reliable,
  transient local, keep last 1, itself with the type hash: its GID, and per node the name, the
  namespace and the GIDs of the node's readers and writers.  It is republished whenever the node's
  set of endpoints changes (node created, publisher or subscription created, node destroyed: an
  empty node list), as ``rmw_dds_common::Context`` does.  A GID is the 16-byte DDS GUID (prefix and
  entity id; Jazzy's ``RMW_GID_STORAGE_SIZE``).  The discovery writer itself belongs to no node.

ROS 2 Humble differs (documented, not implemented): ``Gid.data`` is ``char[24]`` (the GUID in the
first 16 bytes, zeros after), and there is no type hash in USER_DATA (type hashes came with Iron).
"""
from __future__ import annotations

import dataclasses
import math
import os
import sys
import threading
import time
from collections import deque
from typing import Any, Callable, Optional

from moose.params import ParamError

from .base import WAKE_POLL, Handle, NodeBase, Publisher, check_period
from .discovery import Discovery
from .names import CLOCK_TOPIC, CLOCK_TYPE, dds_topic_name
from .qos import QOS_CLOCK_READER, QOS_DEFAULT, QOS_LATCHED, Qos

DISCOVERY_TOPIC = "ros_discovery_info"
"""rmw_dds_common's graph topic (a DDS topic name without ROS conventions)."""
DISCOVERY_TYPE = "rmw_dds_common/msg/ParticipantEntitiesInfo"
DISCOVERY_QOS = QOS_LATCHED
"""rmw_cyclonedds' discovery writer: reliable, transient local, keep last 1."""
ENCLAVE = "/"
"""The security enclave every participant announces (rmw's default: no security)."""
GID_SIZE = 16
"""Bytes of a GID on ROS 2 Jazzy (``RMW_GID_STORAGE_SIZE``; Humble: 24)."""


def participant_user_data(enclave: str = ENCLAVE) -> bytes:
    """The participant's USER_DATA as rmw_cyclonedds writes it."""
    return f"enclave={enclave};".encode()


def endpoint_user_data(type_name: str) -> bytes:
    """A writer's or reader's USER_DATA as rmw_cyclonedds writes it: ``typehash=RIHS01_…;``."""
    from ..interfaces import type_hash

    return f"typehash={type_hash(type_name)};".encode()


def gid(guid: Any) -> list[int]:
    """The ``rmw_dds_common/msg/Gid`` data of a DDS entity's GUID (a :class:`uuid.UUID`)."""
    return list(guid.bytes[:GID_SIZE].ljust(GID_SIZE, b"\0"))



MATCH_RETRIES = 10
"""Tries of :func:`matched_subscriptions` (the count only grows while readers match: it settles at once)."""


def matched_subscriptions(writer: Any) -> int:
    """How many subscriptions ``writer`` is matched with.  cyclonedds-python's ``get_matched_subscriptions`` asks the
    count, sizes a buffer for it and asks again; a reader that matches in between makes the second answer larger than
    the buffer, and it raises IndexError (a node of the fault matrix died of it at start-up, its graph then stuck).
    That only happens while readers are matching: ask again."""
    for _ in range(MATCH_RETRIES - 1):
        try:
            return len(writer.get_matched_subscriptions())
        except IndexError:
            continue
    return len(writer.get_matched_subscriptions())


def acknowledged(writer: Any, timeout: float) -> bool:
    """Whether every reliable reader matched with ``writer`` acknowledged all it wrote, waiting up to ``timeout``
    seconds.  cyclonedds-python (0.10) answers a timeout with an AttributeError of its own (its ``wait_for_acks``
    looks up ``DDS_RETCODE_TIMEOUT`` on Python's ``Exception``): that is a timeout too."""
    try:
        return bool(writer.wait_for_acks(int(max(timeout, 0.0) * 1e9)))
    except AttributeError:
        return False


class _Timer:
    """A timer of the DDS executor: ``callback`` every ``period`` s of the node's timer clock."""

    def __init__(self, period: float, callback: Callable[[], None], start: float) -> None:
        self.period, self.callback, self.next = check_period(period), callback, start + check_period(period)
        self.cancelled = False

    def due(self, now: float) -> bool:
        """True (and the next deadline set) when the timer fires at ``now``; missed periods are skipped
        on the original grid, as rcl timers do."""
        if self.cancelled or now + 1e-9 < self.next:
            return False
        self.next += self.period * (max(0, math.floor((now - self.next) / self.period + 1e-9)) + 1)
        return True


@dataclasses.dataclass
class _Reader:
    reader: Any
    callback: Callable[[Any], None]
    cls: type
    condition: Any
    depth: int
    active: bool = True


class DdsNode(NodeBase):
    """A node on Cyclone DDS with ROS 2 wire conventions (see the module docstring)."""

    release_limit: Optional[float] = None
    """Seconds the participant's deletion may take before the process ends with status 0; ``None``: no bound (a
    participant in a process that goes on, as the launcher's monitor).  The node runner sets it
    (:data:`moose_ros.nodes.RELEASE_LIMIT`): the process ends after the deletion anyway, and Cyclone DDS 11 can wait
    for it for ever.  Its ``ddsi_stop`` stops the event queue, then deletes what is left and waits, without a bound,
    until every participant is gone; a writer that still has samples not acknowledged then lingers, and its linger
    ends by an event of the stopped queue, or by an acknowledgement that the receive threads, stopped too, never
    take (``ddsi_delete_writer``: the participant is never gone).  In 4 of 89 lockstep launches with nodes
    started by exec, a node hung so in ``ddsi_init.c`` at ``participant_set_cond`` until the node's teardown
    watchdog (gdb, 2026-12-03).  The participant's SPDP dispose is out by then: its peers know it left."""

    def __init__(self, name: str, params_file: Optional[str] = None, overrides: Optional[dict[str, Any]] = None,
                 namespace: Optional[str] = None) -> None:
        from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication, BuiltinTopicDcpsSubscription
        from cyclonedds.core import (
            GuardCondition,
            InstanceState,
            Policy,
            ReadCondition,
            SampleState,
            ViewState,
            WaitSet,
        )
        from cyclonedds.core import Qos as DdsQos
        from cyclonedds.domain import DomainParticipant

        super().__init__(name, params_file, overrides or {}, namespace)
        raw = os.environ.get("ROS_DOMAIN_ID", "").strip() or "0"
        if not raw.isdigit() or int(raw) > 232:
            raise ParamError(f"ROS_DOMAIN_ID = {raw!r} is invalid: expected an integer 0..232")
        self.domain_id = int(raw)
        self.discovery = Discovery.from_environ()
        _create_domain(self.domain_id, self.discovery)
        self.participant = DomainParticipant(self.domain_id, qos=DdsQos(Policy.Userdata(participant_user_data())))
        self._waitset = WaitSet(self.participant)
        self._guard = GuardCondition(self.participant)
        self._waitset.attach(self._guard)
        self._topics: dict[str, Any] = {}        # DDS topic name → Topic
        self._local: dict[str, tuple[str, list[tuple[str, Qos]]]] = {}  # DDS topic → (type, [(kind, qos)])
        self._readers: list[_Reader] = []
        self._sleepers = 0
        """Active subscriptions made with ``wake=False`` (not in the wait set)."""
        self._writers: list[Any] = []
        self._timers: list[_Timer] = []
        self._reported: set[tuple[str, str, str]] = set()
        self._fired: deque[Any] = deque()
        """Watches (:meth:`watch`) whose descriptor became readable, appended by their threads."""
        self._recheck = False
        """A topic was created since the executor's last cycle: compare every discovered endpoint again (once for
        all the topics a node creates at start, not once per topic: reading every endpoint's QoS is slow)."""
        self._sim_now: Optional[float] = None
        self._graph_writer = self._discovery_writer()
        self._gids: dict[str, list[list[int]]] = {"reader": [], "writer": []}
        self._publish_graph(with_node=True)
        self._discovery = []
        for kind, topic in (("publisher", BuiltinTopicDcpsPublication), ("subscription", BuiltinTopicDcpsSubscription)):
            reader = BuiltinDataReader(self.participant, topic)
            fresh = ReadCondition(reader, SampleState.NotRead | ViewState.Any | InstanceState.Alive)
            alive = ReadCondition(reader, SampleState.Any | ViewState.Any | InstanceState.Alive)
            self._waitset.attach(fresh)
            self._discovery.append((kind, reader, fresh, alive))
        if self.use_sim_time:
            self.subscription(CLOCK_TYPE, CLOCK_TOPIC, self._on_clock, QOS_CLOCK_READER)

    # -- entities ------------------------------------------------------------------
    def _topic(self, type_name: str, topic: str, kind: str, qos: Qos) -> tuple[Any, type, str]:
        from cyclonedds.topic import Topic

        from ..interfaces import message_class

        full = self.resolve(topic)
        dds_name = dds_topic_name(full)
        cls = message_class(type_name)
        known = self._topics.get(dds_name)
        if known is not None and known.data_type is not cls:
            raise TypeError(f"topic {full!r} is already used with type {known.data_type.ros_type!r}, not {type_name!r}")
        if known is None:
            known = self._topics[dds_name] = Topic(self.participant, dds_name, cls)
            self._local[dds_name] = (cls.__idl_typename__, [])
        self._local[dds_name][1].append((kind, qos))
        self._recheck = True  # the endpoints already read, against this one: once, in the next executor cycle
        return known, cls, full

    @staticmethod
    def _qos(profile: Qos, writer: bool, type_name: str) -> Any:
        from cyclonedds.core import Policy
        from cyclonedds.core import Qos as DdsQos
        from cyclonedds.util import duration

        policies = [
            (Policy.Reliability.Reliable(duration(milliseconds=100)) if profile.reliable
             else Policy.Reliability.BestEffort),
            Policy.History.KeepLast(profile.depth),
            Policy.Durability.TransientLocal if profile.transient_local else Policy.Durability.Volatile,
            Policy.Userdata(endpoint_user_data(type_name)),
        ]
        if writer:  # as rmw_cyclonedds: XCDR1, no dispose when a writer goes away
            policies += [Policy.DataRepresentation(use_cdrv0_representation=True),
                         Policy.WriterDataLifecycle(autodispose=False)]
        return DdsQos(*policies)

    def describe_discovery(self) -> str:
        return self.discovery.describe()

    def publisher(self, type_name: str, topic: str, qos: Qos = QOS_DEFAULT) -> Publisher:
        from cyclonedds.pub import DataWriter

        from ..interfaces import normalise

        dds_topic, cls, full = self._topic(type_name, topic, "publisher", qos)
        writer = DataWriter(self.participant, dds_topic, qos=self._qos(qos, True, type_name))
        self._writers.append(writer)
        self._gids["writer"].append(gid(writer.guid))
        self._publish_graph(with_node=True)

        def publish(msg: Any) -> None:
            if type(msg) is not cls:
                raise TypeError(f"publishing {type(msg).__name__} on {full!r}, which carries {type_name!r}")
            try:
                writer.write(msg)
            except Exception:  # noqa: BLE001 - numpy values or tuples: retry with plain Python values
                try:
                    writer.write(normalise(msg))
                except Exception as exc:  # noqa: BLE001 - the serialiser raises bare Exception
                    cause = exc.__cause__ or exc
                    raise TypeError(f"cannot publish {type_name} on {full!r}: {exc} ({cause})") from None

        self._track("publisher", full, type_name, qos)
        return Publisher(full, type_name, publish, lambda: matched_subscriptions(writer),
                         lambda timeout: acknowledged(writer, timeout))

    def subscription(self, type_name: str, topic: str, callback: Callable[[Any], None],
                     qos: Qos = QOS_DEFAULT, wake: bool = True) -> Handle:
        from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState
        from cyclonedds.sub import DataReader

        dds_topic, cls, full = self._topic(type_name, topic, "subscription", qos)
        reader = DataReader(self.participant, dds_topic, qos=self._qos(qos, False, type_name))
        condition = ReadCondition(reader, SampleState.Any | ViewState.Any | InstanceState.Any)
        entry = _Reader(reader, callback, cls, condition, qos.depth)
        self._readers.append(entry)
        if wake:
            self._waitset.attach(condition)
        else:  # taken at the next wake-up, WAKE_POLL s at the latest (_wait_time)
            self._sleepers += 1
        self._track("subscription", full, type_name, qos)
        self._gids["reader"].append(gid(reader.guid))
        self._publish_graph(with_node=True)

        def cancel() -> None:  # stops the callbacks; the DDS reader stays until the node goes
            if entry.active:
                entry.active = False
                if wake:
                    self._waitset.detach(condition)
                else:
                    self._sleepers -= 1

        return Handle(cancel)

    def _arm(self, watch: Any) -> None:
        pass  # a fired watch waits in _fired for the executor's next cycle

    def _fire_watch(self, watch: Any) -> None:
        self._fired.append(watch)
        self._guard.set(True)

    def timer(self, period: float, callback: Callable[[], None]) -> Handle:
        timer = _Timer(period, callback, self._timer_now())
        self._timers.append(timer)
        self._guard.set(True)  # re-plan the executor's wait

        def cancel() -> None:
            timer.cancelled = True

        return Handle(cancel)

    # -- graph introspection (ros_discovery_info) -----------------------------------
    def _discovery_writer(self) -> Any:
        from cyclonedds.pub import DataWriter
        from cyclonedds.topic import Topic

        from ..interfaces import message_class

        self._graph_topic = Topic(self.participant, DISCOVERY_TOPIC, message_class(DISCOVERY_TYPE))
        self._graph_reader: Any = None
        self._graph_nodes: dict[bytes, list[tuple[str, str]]] = {}
        return DataWriter(self.participant, self._graph_topic, qos=self._qos(DISCOVERY_QOS, True, DISCOVERY_TYPE))

    def graph_info(self, with_node: bool = True) -> Any:
        """This participant's ``ParticipantEntitiesInfo``: its GID and its node (unless ``with_node`` is
        false: the message of a node being destroyed) with the GIDs of the node's readers and writers."""
        from ..interfaces import make

        nodes = []
        if with_node:
            nodes.append(make("rmw_dds_common/msg/NodeEntitiesInfo", node_namespace=self.namespace, node_name=self.name,
                              reader_gid_seq=[make("rmw_dds_common/msg/Gid", data=g) for g in self._gids["reader"]],
                              writer_gid_seq=[make("rmw_dds_common/msg/Gid", data=g) for g in self._gids["writer"]]))
        return make(DISCOVERY_TYPE, gid=make("rmw_dds_common/msg/Gid", data=gid(self.participant.guid)),
                    node_entities_info_seq=nodes)

    def _publish_graph(self, with_node: bool) -> None:
        self._graph_writer.write(self.graph_info(with_node))

    def node_names(self) -> list[tuple[str, str]]:
        """(namespace, name) of the other nodes in the domain, as their participants announce them on
        ``ros_discovery_info`` (the graph ``ros2 node list`` shows).  The first call starts listening:
        participants found later are returned by later calls (discovery takes a few hundred ms)."""
        from cyclonedds.sub import DataReader

        if self._graph_reader is None:
            self._graph_reader = DataReader(self.participant, self._graph_topic,
                                            qos=self._qos(Qos(reliable=True, depth=1000, transient_local=True), False,
                                                          DISCOVERY_TYPE))
        own = bytes(gid(self.participant.guid))
        for info in self._graph_reader.take(N=1000):
            if hasattr(info, "gid"):
                self._graph_nodes[bytes(info.gid.data)] = [(n.node_namespace, n.node_name)
                                                          for n in info.node_entities_info_seq]
        return sorted({n for key, nodes in self._graph_nodes.items() if key != own for n in nodes})

    # -- discovery checks ----------------------------------------------------------
    def _check_discovered(self, fresh: bool = False) -> list[tuple[str, Any]]:
        """Report remote endpoints on our topics whose type or QoS cannot match ours; returns the
        endpoints read, (kind, DcpsEndpoint), all alive ones unless ``fresh`` (only the new ones)."""
        from cyclonedds.builtin import DcpsEndpoint

        own = str(self.participant.guid)
        seen: list[tuple[str, Any]] = []
        for kind, reader, new, alive in self._discovery:
            for ep in reader.read(N=4096, condition=new if fresh else alive):
                if not isinstance(ep, DcpsEndpoint):
                    continue
                seen.append((kind, ep))
                local = self._local.get(ep.topic_name)
                if local is not None and str(ep.participant_key) != own:
                    self._compare(ep, kind, local)
        return seen

    def count_publishers(self, topic: str) -> int:
        """Publishers on ``topic`` in the graph (this node's included), as rclpy's ``Node.count_publishers``."""
        name = dds_topic_name(self.resolve(topic))
        return sum(1 for kind, ep in self._check_discovered() if kind == "publisher" and ep.topic_name == name)

    def count_subscribers(self, topic: str) -> int:
        """Subscriptions on ``topic`` in the graph (this node's included)."""
        name = dds_topic_name(self.resolve(topic))
        return sum(1 for kind, ep in self._check_discovered() if kind == "subscription" and ep.topic_name == name)

    def _compare(self, ep: Any, kind: str, local: tuple[str, list[tuple[str, Qos]]]) -> None:
        from ..interfaces import ros_type_name

        type_name, endpoints = local
        topic = ep.topic_name[2:] if ep.topic_name.startswith("rt/") else ep.topic_name
        if all(own_kind == kind for own_kind, _qos in endpoints):
            return  # publishers do not talk to publishers, nor subscriptions to subscriptions
        if ep.type_name != type_name:
            self._report((topic, ep.type_name, ""),
                         f"topic {topic!r}: a remote {kind} uses type {ros_type_name(ep.type_name)!r}, this node "
                         f"{ros_type_name(type_name)!r}; they will not communicate")
            return
        reliable, transient = _endpoint_qos(ep.qos, kind)
        for own_kind, qos in endpoints:
            if own_kind == kind:
                continue
            if own_kind == "subscription":  # remote writer, our reader
                if qos.reliable and not reliable:
                    self._report((topic, kind, "reliability"),
                                 f"topic {topic!r}: a remote publisher offers best effort, "
                                 "this subscription requests reliable; they will not communicate")
                if qos.transient_local and not transient:
                    self._report((topic, kind, "durability"), f"topic {topic!r}: a remote publisher offers volatile, "
                                 "this subscription requests transient local; they will not communicate")
            else:  # remote reader, our writer
                if reliable and not qos.reliable:
                    self._report((topic, kind, "reliability"), f"topic {topic!r}: a remote subscription requests "
                                 "reliable, this publisher offers best effort; they will not communicate")
                if transient and not qos.transient_local:
                    self._report((topic, kind, "durability"), f"topic {topic!r}: a remote subscription requests "
                                 "transient local, this publisher offers volatile; they will not communicate")

    def _report(self, key: tuple[str, str, str], text: str) -> None:
        if key not in self._reported:
            self._reported.add(key)
            self.log_error(text)

    # -- time ------------------------------------------------------------------------
    def _on_clock(self, msg: Any) -> None:
        t = msg.clock.sec + 1e-9 * msg.clock.nanosec
        if self._sim_now is not None and t < self._sim_now - 1e-9:
            self.log_info(f"/clock jumped back from {self._sim_now:.3f} s to {t:.3f} s: timers restart")
            for timer in self._timers:
                timer.next = t + timer.period
        self._sim_now = t

    def now(self) -> float:
        """ROS time (s): simulated time with ``use_sim_time`` (0 until the first ``/clock``), else wall time."""
        if self.use_sim_time:
            return self._sim_now if self._sim_now is not None else 0.0
        return time.time()

    def _timer_now(self) -> float:
        """The timers' clock: simulated time, or the monotonic clock (immune to wall-clock steps)."""
        return self.now() if self.use_sim_time else time.monotonic()

    @staticmethod
    def make(type_name: str, **fields: Any) -> Any:
        from ..interfaces import make

        return make(type_name, **fields)

    @staticmethod
    def serialize(msg: Any) -> bytes:
        """The message's CDR (XCDR1 with its encapsulation header), as rosbag2 stores it."""
        return bytes(msg.serialize())

    # -- executor --------------------------------------------------------------------
    def _wait_time(self, limit: float) -> float:
        if self._sleepers:
            limit = min(limit, WAKE_POLL)
        if self.use_sim_time:
            return limit  # simulated-time timers fire when /clock arrives
        pending = [t.next for t in self._timers if not t.cancelled]
        if not pending:
            return limit
        return max(0.0, min(limit, min(pending) - time.monotonic()))

    def _execute(self, wait: float) -> None:
        """Wait up to ``wait`` s for data, a guard trigger or the next timer; run what is ready."""
        from cyclonedds.util import duration

        if wait > 0:
            self._waitset.wait(duration(seconds=wait))
        if self._guard.read():
            self._guard.set(False)
        if self._recheck:  # endpoints of this node created since the last cycle: every remote one again
            self._recheck = False
            self._check_discovered()
        for _kind, _reader, condition, _alive in self._discovery:
            if condition.triggered:
                self._check_discovered(fresh=True)
                break
        batch: list[tuple[int, int, Callable[[Any], None], Any]] = []
        for index, entry in enumerate(list(self._readers)):
            if not entry.active:
                continue
            for sample in entry.reader.take(N=max(entry.depth, 64)):
                if isinstance(sample, entry.cls):  # skip dispose/unregister notifications
                    info = getattr(sample, "sample_info", None)
                    batch.append((getattr(info, "source_timestamp", 0), index, entry.callback, sample))
        batch.sort(key=lambda item: (item[0], item[1]))  # publication order across topics
        for _stamp, _index, callback, sample in batch:
            if self._stop.is_set():
                return
            callback(sample)
            self._fire_timers()
        while self._fired and not self._stop.is_set():
            self._fired.popleft().done()
        self._fire_timers()

    def _fire_timers(self) -> None:
        if self.use_sim_time and self._sim_now is None:
            return
        now = self._timer_now()
        for timer in list(self._timers):
            if timer.due(now) and not self._stop.is_set():
                timer.callback()

    def spin_once(self, timeout: float) -> None:
        """Run callbacks and timers for ``timeout`` seconds (returns early on ``shutdown``)."""
        deadline = time.monotonic() + timeout
        with self._running():
            while not self._stop.is_set():
                remaining = deadline - time.monotonic()
                self._execute(self._wait_time(max(remaining, 0.0)))
                if remaining <= 0:
                    break

    def spin_some(self) -> None:
        with self._running():
            self._execute(0.0)

    def spin(self, until: Optional[Callable[[], bool]] = None) -> None:
        """Run callbacks and timers until ``shutdown()`` or ``until()`` is true (checked at least every 0.1 s)."""
        with self._running():
            while not self._stop.is_set() and not (until and until()):
                self._execute(self._wait_time(0.1))

    def _wake(self) -> None:
        self._guard.set(True)

    def _release(self) -> None:
        """Delete the DDS entities."""
        participant = self.participant
        try:  # as rmw_destroy_node: announce the node gone before the participant goes (bounded wait for acks)
            self._publish_graph(with_node=False)
            from cyclonedds.util import duration

            self._graph_writer.wait_for_acks(duration(milliseconds=200))
        except Exception:  # noqa: BLE001 - the participant is deleted below in any case
            pass
        # deleting the participant deletes its readers, writers, topics and waitset in Cyclone DDS
        overrun = None
        if self.release_limit is not None:  # Cyclone's deletion runs in C with the interpreter's lock released
            overrun = threading.Timer(self.release_limit, self._release_overrun)
            overrun.daemon = True
            overrun.start()
        participant.__del__()
        if overrun is not None:
            overrun.cancel()
        self._readers, self._writers, self._topics, self._discovery = [], [], {}, []

    def _release_overrun(self) -> None:
        """The participant's deletion outlasted :attr:`release_limit`: say so and end the process (status 0)."""
        print(f"{self.name}: Cyclone DDS's participant deletion did not end within {self.release_limit:g} s (a "
              "writer still lingering when ddsi_stop stopped the event queue): exiting", file=sys.stderr, flush=True)
        os._exit(0)


_DOMAINS: dict[int, tuple[Optional[str], Any]] = {}
"""The Cyclone DDS domains this process created: id → (configuration, Domain), kept for the process's life unless
:func:`close_domain` deletes one."""


def close_domain(domain_id: int) -> bool:
    """Delete this process's Cyclone DDS domain ``domain_id`` (its threads and sockets) when no participant of this
    process is left in it (a node's, or any other); whether it did.  For a process that moves from domain to
    domain: the test suite gives each test a domain of its own, and a test worker kept every domain its in-process
    launches made (42 and 359 file descriptors after a quarter of the suite), each with its discovery port bound,
    which no other test could then claim.  A node process never calls it: it ends through
    :func:`moose.exiting.end_process` without deleting its domain (a deletion that can hang in Cyclone DDS)."""
    known = _DOMAINS.get(domain_id)
    if known is None or known[1].get_participants():
        return False
    del _DOMAINS[domain_id]
    known[1].__del__()
    return True


WRITER_LINGER = "100ms"
"""How long deleting a reliable writer waits for its readers to acknowledge what it sent (Cyclone DDS's
``Internal/WriterLingerDuration``, 1 s by default).  A reader in a process that was killed never acknowledges and
stays matched until its lease expires, so every writer it read lingered the whole second at shutdown: with the
simulator killed, the other nodes of the lockstep graph took 4–5.3 s to end after SIGTERM at load average 28 (two of
them past the launcher's 5 s grace, so SIGKILLed), against 1.2–1.7 s with 50 ms.  A live reader on this host
acknowledges within milliseconds.  A ``CYCLONEDDS_URI`` can set it again (it is read after this)."""


def _create_domain(domain_id: int, discovery: Discovery) -> None:
    """Create domain ``domain_id`` with ``discovery``'s configuration, once per process; a later node of the
    process must ask for the same configuration (a :class:`ParamError` otherwise, as rmw_cyclonedds refuses
    nodes with other discovery options in one domain)."""
    from cyclonedds.core import DDSException
    from cyclonedds.domain import Domain

    linger = f"<CycloneDDS><Domain><Internal><WriterLingerDuration>{WRITER_LINGER}</WriterLingerDuration></Internal>" \
             "</Domain></CycloneDDS>"
    config = ",".join(p for p in (linger, discovery.cyclone_config()) if p)
    known = _DOMAINS.get(domain_id)
    if known is not None:
        if known[0] != config:
            raise ParamError(f"DDS domain {domain_id} already runs in this process with other discovery settings; "
                             f"a node cannot join it with {discovery.describe()}")
        return
    try:
        _DOMAINS[domain_id] = (config, Domain(domain_id, config))
    except DDSException as exc:
        raise ParamError(f"Cyclone DDS cannot create domain {domain_id} with discovery {discovery.describe()}: {exc} "
                         "(is CYCLONEDDS_URI valid, and was no participant of this domain made outside moose_ros "
                         "first?)") from None


def _endpoint_qos(qos: Any, kind: str) -> tuple[bool, bool]:
    """(reliable, transient-local-or-stronger) of a discovered endpoint; DDS defaults when absent
    (writers reliable, readers best effort; volatile)."""
    from cyclonedds.core import Policy

    reliable, transient = kind == "publisher", False
    if qos is not None:
        try:
            rel = qos[Policy.Reliability]
        except (KeyError, TypeError):
            rel = None
        if rel is not None:
            reliable = "BestEffort" not in repr(rel)
        try:
            dur = qos[Policy.Durability]
        except (KeyError, TypeError):
            dur = None
        if dur is not None:
            transient = "Volatile" not in repr(dur)
    return reliable, transient
