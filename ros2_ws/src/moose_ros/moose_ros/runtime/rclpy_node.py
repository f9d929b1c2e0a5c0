"""The rclpy backend: the runtime's node API on a real ROS 2 node (generated message classes, parameters
visible to ``ros2 param`` and its ``rcl_interfaces`` services, rclpy's time source).

The executor is a single thread that behaves like the DDS backend's (:mod:`.dds`): each turn waits
for work with rclpy's executor, then takes every message that is ready on every subscription of the
node (rclpy's time source's ``/clock`` reader included) and runs their callbacks in publication
order (source timestamps), not in rclpy's order (one message per subscription and wait, in the
order the subscriptions were created).  A node that fuses several topics, such as the observer,
therefore sees its samples in the order they were sent on both runtimes, and ``now()`` in a callback
is the simulated time of the last ``/clock`` published before that message.  Timers are rclpy's
(on the node's clock, so simulated time is honoured); one that is due runs after the messages
taken before it.

Discovery is ROS 2's own (``ROS_AUTOMATIC_DISCOVERY_RANGE``, ``ROS_STATIC_PEERS``), with this project's
default: while the node initialises rclpy and creates its node (the RMW's participant) it sets the variables of
:meth:`.discovery.Discovery.rclpy_environment` (``LOCALHOST`` when the range is unset: on Fast DDS the profile
that binds every socket to 127.0.0.1, on rmw_cyclonedds the loopback binding in ``CYCLONEDDS_URI``) and restores
the environment afterwards, so a node started by ``ros2 run``/``ros2 launch`` stays on this host unless the user
opts in.  On Fast DDS it then checks that every UDP socket the participant opened is bound to 127.0.0.1, and
refuses to run otherwise."""
from __future__ import annotations

import contextlib
import copy
import functools
import itertools
import os
import time
from typing import Any, Callable, Iterator, Optional

from moose.params import ParamError

from .base import Handle, NodeBase, Publisher, check_period, flatten_params, set_dotted
from .discovery import FASTDDS_PROFILE_VARIABLES, FASTDDS_RMWS, LOOPBACK, Discovery, udp_bindings
from .names import CLOCK_TOPIC, CLOCK_TYPE
from .qos import QOS_CLOCK_READER, QOS_DEFAULT, Qos


@contextlib.contextmanager
def _environment(variables: dict[str, str]) -> Iterator[None]:
    """``os.environ`` with ``variables`` set, restored afterwards (so a process this one starts later reads the
    user's settings, not the encoding of them for this node's RMW)."""
    saved = {key: os.environ.get(key) for key in variables}
    os.environ.update(variables)
    try:
        yield
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


READ_ONLY_REASON = "read once when the node starts: restart the node to change it"
"""Why every parameter of an rclpy node is read-only (its descriptor's ``additional_constraints``, the reason a
refused ``set_parameters`` gives)."""

MAX_TAKE = 64
"""Messages taken from one subscription per executor turn at most, as the DDS executor takes at most
``max(depth, 64)`` samples per reader and turn (keep-last depths bound it first)."""


EVENT_PERIOD = 1.0
"""Wall-clock seconds (monotonic) between the executor's waits that include the node's QoS event handlers (an
incompatible QoS or type reported by the middleware is logged at most about this much later than rclpy logs it)."""


@functools.cache
def _events_class() -> Any:
    """The class of :class:`RclpyNode`'s event waitable (a subclass of rclpy's ``Waitable``, defined once rclpy is
    imported, when the first node is made)."""
    from rclpy.waitable import NumberOfEntities, Waitable

    class Events(Waitable):
        """The QoS event handlers rclpy makes by default for each publisher and subscription of the node's (they
        log a remote endpoint's incompatible QoS or type), as one waitable that joins a wait at most every
        :data:`EVENT_PERIOD`.  rclpy's executor builds a new wait set for every wait, in Python, at a cost per
        waitable (enter, count, add, ask whether ready, leave): two handlers per endpoint cost a node of the graph
        more CPU time than the rest of each wait (docs/ros2.md, Runtime).  An event that happens meanwhile stays
        pending in the middleware and is taken at the next wait that includes it.  Handlers and callbacks are
        rclpy's own (``PublisherEventCallbacks``, ``SubscriptionEventCallbacks``): the warnings are the same.  The
        endpoints rclpy makes itself (``/parameter_events``, the time source's ``/clock``) keep theirs."""

        def __init__(self, group: Any) -> None:
            super().__init__(group)
            self._handlers: tuple[Any, ...] = ()  # replaced, never changed: a wait keeps the one it entered
            self._waiting: tuple[Any, ...] = ()  # the handlers of the current wait
            self._ready: list[Any] = []
            self._due = 0.0  # time.monotonic() from which the next wait includes the handlers

        def add(self, callbacks: Any, entity: Any) -> list[Any]:
            """Wait on the handlers that rclpy's ``callbacks`` class (``PublisherEventCallbacks`` or
            ``SubscriptionEventCallbacks``) makes by default for ``entity`` (a publisher or subscription made
            without them) too; returns them."""
            handlers = callbacks().create_event_handlers(self.callback_group, entity.handle, entity.topic)
            self._handlers += tuple(handlers)
            return handlers

        def remove(self, handlers: list[Any]) -> None:
            """Stop waiting on ``handlers`` and destroy them (once no wait uses them)."""
            self._handlers = tuple(h for h in self._handlers if h not in handlers)
            for handler in handlers:
                handler.destroy()

        def destroy(self) -> None:
            """Destroy every handler (before the node)."""
            self.remove(list(self._handlers))

        def __enter__(self) -> None:
            now = time.monotonic()
            self._waiting = self._handlers if now >= self._due else ()
            if self._waiting:
                self._due = now + EVENT_PERIOD
            for handler in self._waiting:
                handler.__enter__()

        def __exit__(self, *exc: Any) -> None:
            for handler in self._waiting:
                handler.__exit__(*exc)

        def get_num_entities(self) -> Any:
            return NumberOfEntities(num_events=len(self._waiting))

        def add_to_wait_set(self, wait_set: Any) -> None:
            for handler in self._waiting:
                handler.add_to_wait_set(wait_set)

        def is_ready(self, wait_set: Any) -> bool:
            self._ready = [handler for handler in self._waiting if handler.is_ready(wait_set)]
            return bool(self._ready)

        def take_data(self) -> list[tuple[Any, Any]]:
            ready, self._ready = self._ready, []
            return [(handler, handler.take_data()) for handler in ready]

        async def execute(self, taken: list[tuple[Any, Any]]) -> None:
            for handler, data in taken:
                await handler.execute(data)

    return Events


class RclpyNode(NodeBase):
    """The same API on rclpy (ROS 2 installed): generated message classes, its own single-threaded executor."""

    def __init__(self, name: str, params_file: Optional[str] = None, overrides: Optional[dict[str, Any]] = None,
                 namespace: Optional[str] = None) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node
        from rclpy.parameter import Parameter

        super().__init__(name, params_file, overrides or {}, namespace)
        self._rclpy = rclpy
        self.discovery = Discovery.from_environ()
        # our --params file and overrides become parameter overrides (they win over --ros-args ones),
        # so use_sim_time reaches rclpy's TimeSource when the node is constructed
        given = []
        for key, value in flatten_params(self._params).items():
            try:
                given.append(Parameter(key, value=value))
            except (TypeError, ValueError) as exc:
                raise ParamError(f"{name}.{key} = {value!r} is invalid for ROS 2 parameters: {exc}") from None
        self._owns_context = not rclpy.ok()
        before = udp_bindings() if self._owns_context else None
        applied = self.discovery.rclpy_environment() if self._owns_context else {}
        with _environment(applied):
            if self._owns_context:  # rcl reads the range in rclpy.init, the RMW its profile with the participant
                rclpy.init(args=None)  # sys.argv: `ros2 run/launch` pass --ros-args (params files, remaps) there
            self.node = Node(name, namespace=None if self.namespace == "/" else self.namespace,
                             parameter_overrides=given, automatically_declare_parameters_from_overrides=True)
        self.rmw = rclpy.get_rmw_implementation_identifier()
        try:
            self._confinement = self._check_confinement(before, applied.get(FASTDDS_PROFILE_VARIABLES[0]))
        except ParamError:
            self.node.destroy_node()
            if self._owns_context:
                rclpy.try_shutdown()
            raise
        self._params = {}
        for dotted, parameter in self.node.get_parameters_by_prefix("").items():
            set_dotted(self._params, dotted, parameter.value)
        self.use_sim_time = bool(self.node.get_parameter("use_sim_time").value)
        self._declaring = False
        self._freeze_parameters()
        if self.use_sim_time:  # rclpy's time source reads /clock with this QoS (as the DDS backend's reader)
            self._track("subscription", CLOCK_TOPIC, CLOCK_TYPE, QOS_CLOCK_READER)
        self._events = _events_class()(self.node.default_callback_group)
        self.node.add_waitable(self._events)
        self._executor = SingleThreadedExecutor()
        self._executor.add_node(self.node)
        self._pending: list[tuple[int, int, int, Callable[[Any], None], Any]] = []
        self._indices = itertools.count()  # of the subscriptions, in the order they were queued (created)
        self._sequence = itertools.count()
        self._worked = False
        self._condition = lambda: self._worked  # one object: rclpy compares the wait's arguments

    def _freeze_parameters(self) -> None:
        """Make every parameter read-only (its descriptor, as ``ros2 param describe`` shows it) and refuse any
        later change with :data:`READ_ONLY_REASON`: the node read its parameters once, and one set at runtime would
        be reported by ``get_parameters`` but not used (``simulation.planner`` on ``weight_fbl``), or would switch
        what the node runs on under it (``use_sim_time``: its clock jumps to wall time)."""
        for name in self.node.get_parameters_by_prefix(""):
            descriptor = copy.copy(self.node.describe_parameter(name))
            if not descriptor.read_only:
                descriptor.read_only = True
                descriptor.additional_constraints = READ_ONLY_REASON
                self.node.set_descriptor(name, descriptor)
        self.node.add_on_set_parameters_callback(self._refuse_change)

    def _refuse_change(self, parameters: list[Any]) -> Any:
        """The set-parameters callback: a declaration of this node's own (:meth:`declare_parameter`) passes, any
        other change is refused with the reason."""
        from rcl_interfaces.msg import SetParametersResult

        if self._declaring:
            return SetParametersResult(successful=True)
        names = ", ".join(p.name for p in parameters)
        return SetParametersResult(successful=False, reason=f"{names}: {READ_ONLY_REASON}")

    def _check_confinement(self, before: Optional[dict[str, tuple[str, int]]], profile: Optional[str]) -> str:
        """With a loopback ``profile`` applied on Fast DDS: that every UDP socket opened since ``before`` (this
        process's sockets before rclpy started) is bound to 127.0.0.1, else a :class:`ParamError`; what was checked,
        for the log."""
        if not self._owns_context:
            return "; rclpy was initialised before this node: its settings are not moose's"
        if profile is None or self.rmw not in FASTDDS_RMWS:
            return ""
        after = udp_bindings()
        if before is None or after is None:
            return "; its sockets not checked (no /proc)"
        opened = [address for inode, address in after.items() if inode not in before]
        outside = sorted({f"{host}:{port}" for host, port in opened if host != LOOPBACK})
        if outside:
            raise ParamError(f"Fast DDS did not apply {profile}: UDP sockets bound to {', '.join(outside)}; refusing "
                             "to run a node that the network can reach (ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET or "
                             "ROS_STATIC_PEERS opt in)")
        return f"; {len(opened)} UDP sockets, all on {LOOPBACK}"

    def describe_discovery(self) -> str:
        return self.discovery.describe(self.rmw) + self._confinement

    @staticmethod
    def _class(type_name: str) -> Any:
        import importlib

        from ..interfaces import UnknownMessageType, check_type_name

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
        from rclpy.event_handler import PublisherEventCallbacks

        pub = self.node.create_publisher(cls, full, self._qos(qos),
                                         event_callbacks=PublisherEventCallbacks(use_default_callbacks=False))
        self._events.add(PublisherEventCallbacks, pub)

        def publish(msg: Any) -> None:
            if type(msg) is not cls:
                raise TypeError(f"publishing {type(msg).__name__} on {full!r}, which carries {type_name!r}")
            pub.publish(msg)

        def acknowledged(timeout: float) -> bool:
            from rclpy.duration import Duration

            return bool(pub.wait_for_all_acked(Duration(nanoseconds=int(max(timeout, 0.0) * 1e9))))

        self._track("publisher", full, type_name, qos)
        return Publisher(full, type_name, publish, pub.get_subscription_count, acknowledged)

    def subscription(self, type_name: str, topic: str, callback: Callable[[Any], None],
                     qos: Qos = QOS_DEFAULT, wake: bool = True) -> Handle:
        from rclpy.event_handler import SubscriptionEventCallbacks

        full = self.resolve(topic)
        sub = self.node.create_subscription(self._class(type_name), full, callback, self._qos(qos),
                                            event_callbacks=SubscriptionEventCallbacks(use_default_callbacks=False))
        handlers = self._events.add(SubscriptionEventCallbacks, sub)
        self._track("subscription", full, type_name, qos)

        def cancel() -> None:
            self._events.remove(handlers)
            self.node.destroy_subscription(sub)

        return Handle(cancel)

    def timer(self, period: float, callback: Callable[[], None]) -> Handle:
        timer = self.node.create_timer(check_period(period), callback)  # on the node's clock: sim time honoured
        return Handle(timer.cancel)

    def _arm(self, watch: Any) -> None:
        watch.backend = self.node.create_guard_condition(watch.done)  # the executor runs it when triggered

    def _fire_watch(self, watch: Any) -> None:
        watch.backend.trigger()  # rcl guard conditions may be triggered from any thread

    def declare_parameter(self, name: str, default: Any = None) -> Any:
        from rcl_interfaces.msg import ParameterDescriptor

        value = super().declare_parameter(name, default)
        if value is not None and not self.node.has_parameter(name):  # visible to `ros2 param`, read-only
            self._declaring = True
            try:
                self.node.declare_parameter(name, value, ParameterDescriptor(
                    read_only=True, additional_constraints=READ_ONLY_REASON))
            except Exception as exc:  # noqa: BLE001 - rclpy's parameter exceptions have no common base
                raise ParamError(f"{self.name}.{name} = {value!r} cannot be declared: {exc}") from None
            finally:
                self._declaring = False
        return value

    def node_names(self) -> list[tuple[str, str]]:
        """(namespace, name) of the other nodes in the graph (``ros2 node list``)."""
        own = (self.namespace, self.name)
        return sorted({(ns, name) for name, ns in self.node.get_node_names_and_namespaces() if (ns, name) != own})

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

    @staticmethod
    def serialize(msg: Any) -> bytes:
        """The message's CDR with its encapsulation header, as rosbag2 stores it (rmw's serialisation)."""
        from rclpy.serialization import serialize_message

        return bytes(serialize_message(msg))

    def log_info(self, text: str) -> None:
        self.node.get_logger().info(text)

    def log_warn(self, text: str) -> None:
        self.node.get_logger().warning(text)

    def log_error(self, text: str) -> None:
        self.node.get_logger().error(text)

    # -- executor --------------------------------------------------------------------
    def _queue_subscriptions(self) -> None:
        """Give every subscription of the node not seen yet a callback that queues its message, and
        every other message the subscription holds, with their source timestamps (the original
        callback runs in :meth:`_flush`)."""
        for sub in self.node.subscriptions:
            if getattr(sub.callback, "queues_for", None) is self:
                continue
            index = next(self._indices)

            def queue(msg: Any, info: dict, sub: Any = sub, callback: Callable[[Any], None] = sub.callback,
                      index: int = index) -> None:
                for _ in range(MAX_TAKE):
                    self._pending.append((int(info["source_timestamp"]), index, next(self._sequence), callback, msg))
                    with sub.handle:  # what rclpy's executor does to take one message
                        taken = sub.handle.take_message(sub.msg_type, sub.raw)
                    if taken is None:
                        break
                    msg, info = taken

            queue.queues_for = self  # type: ignore[attr-defined]  # a marker on the function; mypy has no such attributes
            sub.callback = queue  # two parameters: rclpy passes the message info

    def _flush(self) -> None:
        """Run the queued messages' callbacks in publication order (source timestamp, then subscription)."""
        batch, self._pending = sorted(self._pending, key=lambda item: item[:3]), []
        for _stamp, _index, _seq, callback, msg in batch:
            if self._stop.is_set():
                return
            callback(msg)

    def _next(self, timeout: float, nodes: Optional[list[Any]] = None,
              condition: Callable[[], bool] = lambda: False) -> Optional[tuple[Any, Any]]:
        """rclpy's executor's next ready entity, ``(handler, entity)``, waiting up to ``timeout`` s on ``nodes`` (all
        of the executor's if ``None``); ``None`` once the wait found nothing more, ``condition()`` is true, or the
        executor or its context was shut down."""
        from rclpy.executors import ConditionReachedException, ShutdownException, TimeoutException
        from rclpy.impl.implementation_singleton import rclpy_implementation

        try:
            handler, entity, _node = self._executor.wait_for_ready_callbacks(timeout, nodes, condition)
        except (TimeoutException, ConditionReachedException, ShutdownException):
            return None
        except rclpy_implementation.RCLError:  # the context ended under the wait: rclpy's SIGINT handler shuts it
            if self._rclpy.ok():  # down at any moment, also between spin()'s check of ok() and this wait
                raise
            return None
        return handler, entity

    def _turn(self, timeout: float) -> None:
        """Wait up to ``timeout`` s for work, run what that one wait found ready (subscriptions queue
        their messages; a timer runs after the messages queued before it), then the queued messages
        in publication order."""
        from rclpy.timer import Timer

        self._queue_subscriptions()
        self._worked = False
        while not self._stop.is_set():
            # the same arguments each call: rclpy goes on through one wait's ready entities, and once they
            # are done the condition (work was done) ends the turn instead of a new wait
            ready = self._next(timeout, None, self._condition)
            if ready is None:
                break
            handler, entity = ready
            self._worked = True
            if isinstance(entity, Timer):
                self._flush()
            handler()
            if handler.exception() is not None:
                raise handler.exception()
        if self._worked:  # rclpy's handlers trigger the executor's guard condition (for a multi-threaded executor to
            # wait on their entities again): a wait on no node takes that wake-up for a fraction of the cost of the
            # full wait set, which the next turn's wait would build to find nothing else ready
            self._next(0.0, [])
        self._flush()

    def spin_once(self, timeout: float) -> None:
        """Run callbacks and timers for ``timeout`` seconds (returns early on ``shutdown``)."""
        from rclpy.executors import ExternalShutdownException

        deadline = time.monotonic() + timeout
        with self._running():
            try:
                while not self._stop.is_set() and self._rclpy.ok():
                    remaining = deadline - time.monotonic()
                    if remaining <= 0:
                        break
                    self._turn(min(remaining, 0.1))
            except ExternalShutdownException:
                pass

    def spin_some(self) -> None:
        from rclpy.executors import ExternalShutdownException

        with self._running():
            try:
                if not self._stop.is_set() and self._rclpy.ok():
                    self._turn(0.0)
            except ExternalShutdownException:
                pass

    def spin(self, until: Optional[Callable[[], bool]] = None) -> None:
        """Run callbacks and timers until ``shutdown()``, the end of the rclpy context (Ctrl-C) or
        ``until()`` is true (checked at least every 0.1 s)."""
        from rclpy.executors import ExternalShutdownException

        with self._running():
            try:
                while self._rclpy.ok() and not self._stop.is_set() and not (until and until()):
                    self._turn(0.1)
            except ExternalShutdownException:
                pass

    def _wake(self) -> None:
        self._executor.wake()

    def _release(self) -> None:
        """Destroy the node and its executor (and the rclpy context if this node created it)."""
        self._executor.remove_node(self.node)
        self._executor.shutdown()
        self._events.destroy()
        self.node.destroy_node()
        if self._owns_context:
            self._rclpy.try_shutdown()
