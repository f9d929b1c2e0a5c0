"""The small runtime every node is written against: rclpy when importable, else Cyclone DDS.

API (both backends, see :class:`_NodeBase`):

- ``create_node(name, params_file=None, overrides=None, namespace=None)``
- ``publisher(type, topic, qos)`` → :class:`Publisher` (call it with a message, or ``.publish(msg)``)
- ``subscription(type, topic, callback, qos)``, ``timer(period, callback)`` → handles with ``cancel()``
- ``declare_parameter(name, default)``, ``get_parameter(name)``, ``param(name, default)``, ``parameters``
- ``now()`` (s; simulated time when ``use_sim_time``), ``log_info/log_warn/log_error``
- ``count_publishers(topic)``, ``count_subscribers(topic)`` (graph introspection)
- ``spin(until)``, ``spin_once(timeout)``, ``shutdown()``, ``make(type, **fields)``

Message types are named ``pkg/msg/Type``; message objects have the ``.msg`` field names on both
backends (generated rclpy classes, or the DDS dataclasses of :mod:`moose_ros.interfaces`).

The DDS backend follows rmw_cyclonedds: the ROS topic ``/ns/x`` is the DDS topic ``rt/ns/x``,
type names are ``pkg::msg::dds_::Type_``, data is XCDR1 little-endian CDR, the domain comes from
``ROS_DOMAIN_ID`` (default 0) and QoS profiles map one to one (:class:`Qos`).  The executor is a
single thread, like rclpy's SingleThreadedExecutor: ``spin`` blocks on a DDS WaitSet (readers,
a guard condition for shutdown) with a timeout up to the next timer, takes what the readers hold
and runs the callbacks in publication order (source timestamps), then the timers that are due.
Samples stay in the DDS reader history until the executor takes them, so keep-last depths act as
in ROS 2 (a slow callback sees the newest samples, not a backlog).  With ``use_sim_time`` the
clock follows ``/clock`` and timers fire on simulated time.

Discovery is watched: a remote endpoint on one of our topics with another type, or with QoS that
cannot match ours (best effort offered to a reliable reader, volatile to a transient-local one),
is reported once with ``log_error``: such endpoints never exchange data.
"""
from __future__ import annotations

import contextlib
import dataclasses
import math
import os
import re
import sys
import threading
import time
from pathlib import Path
from typing import Any, Callable, Optional

from moose.params import ParamError, check, read_ros_params


@dataclasses.dataclass(frozen=True)
class Qos:
    """A ROS 2 QoS profile (the subset the graph uses): reliability, keep-last depth, durability."""

    reliable: bool = True
    depth: int = 10
    transient_local: bool = False

    def __post_init__(self) -> None:
        check("qos.depth", self.depth, lambda d: isinstance(d, int) and not isinstance(d, bool) and d >= 1,
              "an integer >= 1")


QOS_DEFAULT = Qos()
"""rclpy's default: reliable, volatile, keep last 10."""
QOS_SENSOR = Qos(reliable=False, depth=5)
"""rclpy's qos_profile_sensor_data: best effort, keep last 5."""
QOS_LATCHED = Qos(reliable=True, depth=1, transient_local=True)
"""Reliable, transient local, keep last 1 (late joiners get the last sample)."""
QOS_LATCHED_READER = Qos(reliable=True, depth=100, transient_local=True)
"""Reader side of latched topics with many writers (``/diagnostics``): keyless topics share one
history, so a depth of 1 would keep only one writer's late-joiner sample."""
QOS_CLOCK = Qos(reliable=True, depth=1)
"""Writer of ``/clock`` (the simulator)."""
QOS_CLOCK_READER = Qos(reliable=False, depth=1)
"""Reader of ``/clock`` with ``use_sim_time``: best effort, keep last 1 like rclpy's TimeSource, so it
matches reliable and best-effort clock writers (``ros2 bag play --clock``) alike."""

_TOKEN = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


def _check_tokens(what: str, name: str, tokens: list[str]) -> None:
    for token in tokens:
        if not _TOKEN.match(token) or "__" in token:
            raise ValueError(f"{what} {name!r} is invalid: {token!r} is not a name token "
                             "(letters, digits, single underscores; not starting with a digit)")


def resolve_topic(topic: str, namespace: str = "/", node_name: str = "") -> str:
    """Fully qualified ROS name of ``topic``: absolute names stay, relative ones go under ``namespace``,
    ``~`` is the node's private namespace (``namespace/node_name``)."""
    if not isinstance(topic, str) or not topic:
        raise ValueError(f"topic name {topic!r} is invalid: expected a non-empty string")
    ns = normalise_namespace(namespace)
    if topic.startswith("~"):
        if topic not in ("~",) and not topic.startswith("~/"):
            raise ValueError(f"topic name {topic!r} is invalid: '~' must be followed by '/'")
        base = ns.rstrip("/") + "/" + node_name
        rest = topic[2:]
        full = base + ("/" + rest if rest else "")
    elif topic.startswith("/"):
        full = topic
    else:
        full = ns.rstrip("/") + "/" + topic
    if full.endswith("/") or "//" in full:
        raise ValueError(f"topic name {topic!r} is invalid: empty name token")
    _check_tokens("topic name", topic, full.strip("/").split("/"))
    return full


def normalise_namespace(namespace: Optional[str]) -> str:
    """``None``/``""`` → ``/``; ``car1`` → ``/car1``; validated like ROS 2 namespaces."""
    if not namespace or namespace == "/":
        return "/"
    ns = namespace if namespace.startswith("/") else "/" + namespace
    if ns.endswith("/") or "//" in ns:
        raise ValueError(f"namespace {namespace!r} is invalid: empty name token")
    _check_tokens("namespace", namespace, ns.strip("/").split("/"))
    return ns


def dds_topic_name(full_name: str) -> str:
    """rmw_cyclonedds' DDS topic of a fully qualified ROS topic: ``/x/y`` → ``rt/x/y``."""
    return "rt" + full_name


def _flatten(params: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in params.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            out.update(_flatten(value, name + "."))
        else:
            out[name] = value
    return out


def _typed(name: str, value: Any, default: Any) -> Any:
    """``value`` checked against the type of ``default`` (ints pass as floats), as rclpy's declare does."""
    if default is None or value is None:
        return value
    if isinstance(default, bool):
        ok = isinstance(value, bool)
    elif isinstance(default, float):
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        value = float(value) if ok else value
    elif isinstance(default, int):
        ok = isinstance(value, int) and not isinstance(value, bool)
    elif isinstance(default, str):
        ok = isinstance(value, str)
    elif isinstance(default, (list, tuple)):
        ok = isinstance(value, (list, tuple))
    else:
        ok = True
    if not ok:
        raise ParamError(f"{name} = {value!r} is invalid: expected {type(default).__name__} like the default {default!r}")
    return value


class Handle:
    """A subscription or timer; ``cancel()`` stops it."""

    def __init__(self, cancel: Callable[[], None]) -> None:
        self._cancel = cancel

    def cancel(self) -> None:
        self._cancel()


class Publisher:
    """Publishes messages of one type on one topic: ``pub(msg)`` or ``pub.publish(msg)``."""

    def __init__(self, topic: str, type_name: str, publish: Callable[[Any], None],
                 count: Callable[[], int]) -> None:
        self.topic, self.type_name = topic, type_name
        self._publish, self._count = publish, count

    def __call__(self, msg: Any) -> None:
        self._publish(msg)

    def publish(self, msg: Any) -> None:
        self._publish(msg)

    def subscription_count(self) -> int:
        """Number of matched subscriptions (remote and local)."""
        return self._count()


class _NodeBase:
    """Parameters, logging and the spin/shutdown life cycle shared by both backends."""

    def __init__(self, name: str, params_file: Optional[str], overrides: dict[str, Any],
                 namespace: Optional[str]) -> None:
        if not isinstance(name, str) or not _TOKEN.match(name) or "__" in name:
            raise ValueError(f"node name {name!r} is invalid: expected letters, digits and single underscores")
        self.name = name
        self.namespace = normalise_namespace(namespace)
        self._params: dict[str, Any] = read_ros_params(params_file, name) if params_file else {}
        for key, value in overrides.items():
            target = self._params
            *groups, leaf = key.split(".")
            for group in groups:
                target = target.setdefault(group, {})
            target[leaf] = value
        self.use_sim_time = self._sim_time_flag(self._params.get("use_sim_time", False))
        self._stop = threading.Event()
        self._closed = False
        self._spinning = False

    # -- life cycle ----------------------------------------------------------------

    @contextlib.contextmanager
    def _running(self) -> Any:
        """Mark the node as spinning; release it on the way out if ``shutdown`` was asked meanwhile."""
        self._spinning = True
        try:
            yield
        finally:
            self._spinning = False
        if self._stop.is_set():
            self._close()

    def shutdown(self) -> None:
        """Stop spinning (also from a callback or another thread) and release the node's entities."""
        self._stop.set()
        if not self._closed:
            self._wake()
        if not self._spinning:
            self._close()

    def _close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._release()

    def _wake(self) -> None:
        """Interrupt a blocking wait of the executor (backends that wait without a timeout)."""

    def _release(self) -> None:
        raise NotImplementedError

    @staticmethod
    def _sim_time_flag(value: Any) -> bool:
        if not isinstance(value, bool):
            raise ParamError(f"use_sim_time = {value!r} is invalid: expected true or false")
        return value

    @property
    def full_name(self) -> str:
        return self.namespace.rstrip("/") + "/" + self.name

    def resolve(self, topic: str) -> str:
        """The fully qualified name of ``topic`` for this node."""
        return resolve_topic(topic, self.namespace, self.name)

    # -- parameters ----------------------------------------------------------------
    def param(self, name: str, default: Any = None) -> Any:
        """Parameter ``name`` (dotted for nested groups), or ``default``."""
        value: Any = self._params
        for part in name.split("."):
            if not isinstance(value, dict) or part not in value:
                return default
            value = value[part]
        return value

    def declare_parameter(self, name: str, default: Any = None) -> Any:
        """Declare ``name`` with ``default``; returns the file/override value (type-checked against the
        default: a mismatch is a :class:`ParamError` naming the node, parameter and value) or the default."""
        value = _typed(f"{self.name}.{name}", self.param(name, default), default)
        target = self._params
        *groups, leaf = name.split(".")
        for group in groups:
            target = target.setdefault(group, {})
        target[leaf] = value
        return value

    def get_parameter(self, name: str) -> Any:
        """Value of a declared (or file-given) parameter; :class:`ParamError` if there is none."""
        missing = object()
        value = self.param(name, missing)
        if value is missing:
            raise ParamError(f"{self.name}.{name} is not set: declare it or give it in the parameter file")
        return value

    @property
    def parameters(self) -> dict[str, Any]:
        return self._params

    # -- logging ---------------------------------------------------------------------
    def _log(self, level: str, text: str) -> None:
        line = f"[{level}] [{time.time():.6f}] [{self.name}]: {text}\n"
        stream = sys.stdout if level == "INFO" else sys.stderr
        stream.write(line)
        stream.flush()

    def log_info(self, text: str) -> None:
        self._log("INFO", text)

    def log_warn(self, text: str) -> None:
        self._log("WARN", text)

    def log_error(self, text: str) -> None:
        self._log("ERROR", text)


class _Timer:
    def __init__(self, period: float, callback: Callable[[], None], start: float) -> None:
        check("timer.period", period, lambda p: isinstance(p, (int, float)) and math.isfinite(p) and p > 0,
              "a positive number of seconds")
        self.period, self.callback, self.next = float(period), callback, start + float(period)
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


class DdsNode(_NodeBase):
    """A node on Cyclone DDS with ROS 2 wire conventions (see the module docstring)."""

    def __init__(self, name: str, params_file: Optional[str] = None, overrides: Optional[dict[str, Any]] = None,
                 namespace: Optional[str] = None) -> None:
        from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication, BuiltinTopicDcpsSubscription
        from cyclonedds.core import GuardCondition, InstanceState, ReadCondition, SampleState, ViewState, WaitSet
        from cyclonedds.domain import DomainParticipant

        super().__init__(name, params_file, overrides or {}, namespace)
        raw = os.environ.get("ROS_DOMAIN_ID", "").strip() or "0"
        if not raw.isdigit() or int(raw) > 232:
            raise ParamError(f"ROS_DOMAIN_ID = {raw!r} is invalid: expected an integer 0..232")
        self.domain_id = int(raw)
        self.participant = DomainParticipant(self.domain_id)
        self._waitset = WaitSet(self.participant)
        self._guard = GuardCondition(self.participant)
        self._waitset.attach(self._guard)
        self._topics: dict[str, Any] = {}        # DDS topic name → Topic
        self._local: dict[str, tuple[str, list[tuple[str, Qos]]]] = {}  # DDS topic → (type, [(kind, qos)])
        self._readers: list[_Reader] = []
        self._writers: list[Any] = []
        self._timers: list[_Timer] = []
        self._reported: set[tuple[str, str, str]] = set()
        self._sim_now: Optional[float] = None
        self._discovery = []
        for kind, topic in (("publisher", BuiltinTopicDcpsPublication), ("subscription", BuiltinTopicDcpsSubscription)):
            reader = BuiltinDataReader(self.participant, topic)
            fresh = ReadCondition(reader, SampleState.NotRead | ViewState.Any | InstanceState.Alive)
            alive = ReadCondition(reader, SampleState.Any | ViewState.Any | InstanceState.Alive)
            self._waitset.attach(fresh)
            self._discovery.append((kind, reader, fresh, alive))
        if self.use_sim_time:
            self.subscription("rosgraph_msgs/msg/Clock", "/clock", self._on_clock, QOS_CLOCK_READER)

    # -- entities ------------------------------------------------------------------
    def _topic(self, type_name: str, topic: str, kind: str, qos: Qos) -> tuple[Any, type, str]:
        from cyclonedds.topic import Topic

        from .interfaces import message_class

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
        self._check_discovered()
        return known, cls, full

    @staticmethod
    def _qos(profile: Qos, writer: bool) -> Any:
        from cyclonedds.core import Policy, Qos as DdsQos
        from cyclonedds.util import duration

        policies = [
            Policy.Reliability.Reliable(duration(milliseconds=100)) if profile.reliable else Policy.Reliability.BestEffort,
            Policy.History.KeepLast(profile.depth),
            Policy.Durability.TransientLocal if profile.transient_local else Policy.Durability.Volatile,
        ]
        if writer:  # as rmw_cyclonedds: XCDR1, no dispose when a writer goes away
            policies += [Policy.DataRepresentation(use_cdrv0_representation=True),
                         Policy.WriterDataLifecycle(autodispose=False)]
        return DdsQos(*policies)

    def publisher(self, type_name: str, topic: str, qos: Qos = QOS_DEFAULT) -> Publisher:
        from cyclonedds.pub import DataWriter

        from .interfaces import normalise

        dds_topic, cls, full = self._topic(type_name, topic, "publisher", qos)
        writer = DataWriter(self.participant, dds_topic, qos=self._qos(qos, writer=True))
        self._writers.append(writer)

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

        return Publisher(full, type_name, publish, lambda: len(writer.get_matched_subscriptions()))

    def subscription(self, type_name: str, topic: str, callback: Callable[[Any], None],
                     qos: Qos = QOS_DEFAULT) -> Handle:
        from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState
        from cyclonedds.sub import DataReader

        dds_topic, cls, _full = self._topic(type_name, topic, "subscription", qos)
        reader = DataReader(self.participant, dds_topic, qos=self._qos(qos, writer=False))
        condition = ReadCondition(reader, SampleState.Any | ViewState.Any | InstanceState.Any)
        entry = _Reader(reader, callback, cls, condition, qos.depth)
        self._readers.append(entry)
        self._waitset.attach(condition)

        def cancel() -> None:
            if entry.active:
                entry.active = False
                self._waitset.detach(condition)

        return Handle(cancel)

    def timer(self, period: float, callback: Callable[[], None]) -> Handle:
        timer = _Timer(period, callback, self._timer_now())
        self._timers.append(timer)
        self._guard.set(True)  # re-plan the executor's wait

        def cancel() -> None:
            timer.cancelled = True

        return Handle(cancel)

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
        from .interfaces import ros_type_name

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
                    self._report((topic, kind, "reliability"), f"topic {topic!r}: a remote publisher offers best effort, "
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
        from .interfaces import make

        return make(type_name, **fields)

    # -- executor --------------------------------------------------------------------
    def _wait_time(self, limit: float) -> float:
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
        # deleting the participant deletes its readers, writers, topics and waitset in Cyclone DDS
        participant.__del__()
        self._readers, self._writers, self._topics, self._discovery = [], [], {}, []


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


class RclpyNode(_NodeBase):
    """The same API on rclpy (ROS 2 installed): generated message classes, its own single-threaded executor."""

    def __init__(self, name: str, params_file: Optional[str] = None, overrides: Optional[dict[str, Any]] = None,
                 namespace: Optional[str] = None) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node
        from rclpy.parameter import Parameter

        super().__init__(name, params_file, overrides or {}, namespace)
        self._rclpy = rclpy
        self._owns_context = False
        if not rclpy.ok():
            rclpy.init(args=None)  # sys.argv: `ros2 run/launch` pass --ros-args (params files, remaps) there
            self._owns_context = True
        # our --params file and overrides become parameter overrides (they win over --ros-args ones),
        # so use_sim_time reaches rclpy's TimeSource when the node is constructed
        given = []
        for key, value in _flatten(self._params).items():
            try:
                given.append(Parameter(key, value=value))
            except (TypeError, ValueError) as exc:
                raise ParamError(f"{name}.{key} = {value!r} is invalid for ROS 2 parameters: {exc}") from None
        self.node = Node(name, namespace=None if self.namespace == "/" else self.namespace, parameter_overrides=given,
                         automatically_declare_parameters_from_overrides=True)
        self._params = {}
        for dotted, parameter in self.node.get_parameters_by_prefix("").items():
            target = self._params
            *groups, leaf = dotted.split(".")
            for group in groups:
                target = target.setdefault(group, {})
            target[leaf] = parameter.value
        self.use_sim_time = bool(self.node.get_parameter("use_sim_time").value)
        self._executor = SingleThreadedExecutor()
        self._executor.add_node(self.node)

    @staticmethod
    def _class(type_name: str) -> Any:
        import importlib

        from .interfaces import UnknownMessageType, check_type_name

        check_type_name(type_name)
        pkg, kind, name = type_name.split("/")
        try:
            return getattr(importlib.import_module(f"{pkg}.{kind}"), name)
        except (ImportError, AttributeError):
            raise UnknownMessageType(f"message type {type_name!r} is unknown (no generated class {pkg}.{kind}.{name}; "
                                     "is the package built and sourced?)") from None

    @staticmethod
    def _qos(profile: Qos) -> Any:
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

        return QoSProfile(
            history=HistoryPolicy.KEEP_LAST, depth=profile.depth,
            reliability=ReliabilityPolicy.RELIABLE if profile.reliable else ReliabilityPolicy.BEST_EFFORT,
            durability=DurabilityPolicy.TRANSIENT_LOCAL if profile.transient_local else DurabilityPolicy.VOLATILE,
        )

    def publisher(self, type_name: str, topic: str, qos: Qos = QOS_DEFAULT) -> Publisher:
        cls = self._class(type_name)
        full = self.resolve(topic)
        pub = self.node.create_publisher(cls, full, self._qos(qos))

        def publish(msg: Any) -> None:
            if type(msg) is not cls:
                raise TypeError(f"publishing {type(msg).__name__} on {full!r}, which carries {type_name!r}")
            pub.publish(msg)

        return Publisher(full, type_name, publish, pub.get_subscription_count)

    def subscription(self, type_name: str, topic: str, callback: Callable[[Any], None],
                     qos: Qos = QOS_DEFAULT) -> Handle:
        sub = self.node.create_subscription(self._class(type_name), self.resolve(topic), callback, self._qos(qos))
        return Handle(lambda: self.node.destroy_subscription(sub))

    def timer(self, period: float, callback: Callable[[], None]) -> Handle:
        _Timer(period, callback, 0.0)  # the same validation of the period as the DDS backend
        timer = self.node.create_timer(float(period), callback)  # on the node's clock: sim time honoured
        return Handle(timer.cancel)

    def declare_parameter(self, name: str, default: Any = None) -> Any:
        value = super().declare_parameter(name, default)
        if value is not None and not self.node.has_parameter(name):  # visible to `ros2 param`
            try:
                self.node.declare_parameter(name, value)
            except Exception as exc:  # noqa: BLE001 - rclpy's parameter exceptions have no common base
                raise ParamError(f"{self.name}.{name} = {value!r} cannot be declared: {exc}") from None
        return value

    def count_publishers(self, topic: str) -> int:
        return self.node.count_publishers(self.resolve(topic))

    def count_subscribers(self, topic: str) -> int:
        return self.node.count_subscribers(self.resolve(topic))

    def now(self) -> float:
        return self.node.get_clock().now().nanoseconds * 1e-9

    def make(self, type_name: str, **fields: Any) -> Any:
        cls = self._class(type_name)
        known = cls.get_fields_and_field_types()
        unknown = sorted(set(fields) - set(known))
        if unknown:
            raise TypeError(f"{type_name} has no field {unknown[0]!r}; fields: {', '.join(known)}")
        msg = cls()
        for key, value in fields.items():
            setattr(msg, key, value)
        return msg

    def log_info(self, text: str) -> None:
        self.node.get_logger().info(text)

    def log_warn(self, text: str) -> None:
        self.node.get_logger().warning(text)

    def log_error(self, text: str) -> None:
        self.node.get_logger().error(text)

    def spin_once(self, timeout: float) -> None:
        """Run callbacks and timers for ``timeout`` seconds (returns early on ``shutdown``)."""
        deadline = time.monotonic() + timeout
        with self._running():
            while not self._stop.is_set() and self._rclpy.ok():
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    break
                self._executor.spin_once(timeout_sec=min(remaining, 0.1))

    def spin(self, until: Optional[Callable[[], bool]] = None) -> None:
        from rclpy.executors import ExternalShutdownException

        with self._running():
            try:
                while self._rclpy.ok() and not self._stop.is_set() and not (until and until()):
                    self._executor.spin_once(timeout_sec=0.1)
            except ExternalShutdownException:
                pass

    def _release(self) -> None:
        """Destroy the node and its executor (and the rclpy context if this node created it)."""
        self._executor.remove_node(self.node)
        self._executor.shutdown()
        self.node.destroy_node()
        if self._owns_context:
            self._rclpy.try_shutdown()


def backend() -> str:
    """``rclpy`` when ``import rclpy`` works and ``MOOSE_RUNTIME`` is not ``dds``, else ``dds``."""
    choice = os.environ.get("MOOSE_RUNTIME", "").strip().lower()
    if choice not in ("", "dds", "rclpy"):
        raise ParamError(f"MOOSE_RUNTIME = {choice!r} is invalid: expected 'dds' or 'rclpy'")
    if choice == "dds":
        return "dds"
    try:
        import rclpy  # noqa: F401
    except ImportError:
        if choice == "rclpy":
            raise ParamError("MOOSE_RUNTIME = 'rclpy' but rclpy cannot be imported (source the ROS 2 setup)") from None
        return "dds"
    return "rclpy"


def create_node(name: str, params_file: Optional[str] = None, overrides: Optional[dict[str, Any]] = None,
                namespace: Optional[str] = None) -> Any:
    """A node on rclpy when it is importable (and MOOSE_RUNTIME is not ``dds``), else on Cyclone DDS.

    ``params_file``: a ROS 2 parameter YAML (``/**`` and the node's own section); ``overrides``:
    ``{dotted.name: value}`` applied on top.  A missing or malformed file is a :class:`ParamError`.
    """
    if params_file is not None and not Path(params_file).is_file():
        raise ParamError(f"--params {params_file!r}: no such file")
    cls = RclpyNode if backend() == "rclpy" else DdsNode
    return cls(name, params_file, overrides, namespace)
