"""The node base class both backends share: name, namespace, parameters, logging, spin/shutdown life cycle, and
the node API each backend implements (publishers, subscriptions, timers, the clock, messages, the executor)."""
from __future__ import annotations

import abc
import contextlib
import dataclasses
import math
import sys
import threading
import time
from typing import Any, Callable, Optional

from moose.params import ParamError, check, read_ros_params

from .names import check_node_name, normalise_namespace, resolve_topic
from .qos import QOS_DEFAULT, Qos


def flatten_params(params: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested parameter groups as ``{"group.name": value}``."""
    out: dict[str, Any] = {}
    for key, value in params.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            out.update(flatten_params(value, name + "."))
        else:
            out[name] = value
    return out


def set_dotted(params: dict[str, Any], name: str, value: Any) -> None:
    """Set parameter ``name`` (dotted for nested groups) in ``params``, creating the groups on the way."""
    target = params
    *groups, leaf = name.split(".")
    for group in groups:
        target = target.setdefault(group, {})
    target[leaf] = value


def check_period(period: Any) -> float:
    """A timer period in seconds: a finite positive number, else :class:`ParamError`."""
    check("timer.period", period, lambda p: isinstance(p, (int, float)) and math.isfinite(p) and p > 0,
          "a positive number of seconds")
    return float(period)


def typed_value(name: str, value: Any, default: Any) -> Any:
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
        raise ParamError(f"{name} = {value!r} is invalid: "
                         f"expected {type(default).__name__} like the default {default!r}")
    return value


@dataclasses.dataclass(frozen=True)
class Endpoint:
    """A publisher or subscription a node created."""

    kind: str
    """``publisher`` or ``subscription``."""
    topic: str
    """Fully qualified topic name."""
    type: str
    qos: Qos


class Handle:
    """A subscription or timer; ``cancel()`` stops it."""

    def __init__(self, cancel: Callable[[], None]) -> None:
        self._cancel = cancel

    def cancel(self) -> None:
        self._cancel()


class Publisher:
    """Publishes messages of one type on one topic: ``pub(msg)`` or ``pub.publish(msg)``."""

    def __init__(self, topic: str, type_name: str, publish: Callable[[Any], None],
                 count: Callable[[], int], acknowledged: Callable[[float], bool]) -> None:
        self.topic, self.type_name = topic, type_name
        self._publish, self._count, self._acknowledged = publish, count, acknowledged

    def __call__(self, msg: Any) -> None:
        self._publish(msg)

    def publish(self, msg: Any) -> None:
        self._publish(msg)

    def subscription_count(self) -> int:
        """Number of matched subscriptions (remote and local)."""
        return self._count()

    def wait_acknowledged(self, timeout: float) -> bool:
        """Wait up to ``timeout`` seconds until every matched reliable reader has acknowledged every sample published
        (DDS ``wait_for_acknowledgments``; rclpy's ``wait_for_all_acked``); whether they all have.  A writer that is
        deleted takes the samples its readers have not acknowledged with it: what a node says last before it goes
        away waits for this."""
        return self._acknowledged(timeout)


class _Watch:
    """A file descriptor watched for :meth:`NodeBase.watch`: its thread's loop and the executor's side."""

    WAIT = 0.1
    """Longest wait (s) of the thread on the descriptor or on the callback: how soon it sees a shutdown."""

    def __init__(self, fileno: Callable[[], Optional[int]], callback: Callable[[], None], poll: float) -> None:
        self.fileno, self.callback, self.poll = fileno, callback, poll
        self.ran = threading.Event()
        self.cancelled = False
        self.backend: Any = None
        """What the backend keeps for it (rclpy: its guard condition)."""

    def cancel(self) -> None:
        self.cancelled = True

    def done(self) -> None:
        """The executor's side: run the callback, then let the thread wait again."""
        try:
            if not self.cancelled:
                self.callback()
        finally:
            self.ran.set()

    def run(self, stop: threading.Event, fire: Callable[["_Watch"], None]) -> None:
        import select

        while not stop.is_set() and not self.cancelled:
            try:
                fd = self.fileno()
            except (OSError, ValueError, NotImplementedError):
                fd = None
            if fd is None or fd < 0:
                if stop.wait(self.poll):
                    return
            else:
                try:
                    readable, _, _ = select.select([fd], [], [], self.WAIT)
                except (OSError, ValueError):  # closed under us: ask for the descriptor again
                    readable = []
                    stop.wait(self.poll)
                if not readable:
                    continue
            self.ran.clear()
            fire(self)
            while not self.ran.wait(self.WAIT):
                if stop.is_set() or self.cancelled:
                    return


WAKE_POLL = 0.02
"""Seconds at most before the executor takes what arrived on a subscription made with ``wake=False``: the bound on
its delay when nothing else wakes the executor."""


class NodeBase(abc.ABC):
    """Parameters, logging and the spin/shutdown life cycle shared by both backends."""

    def __init__(self, name: str, params_file: Optional[str], overrides: dict[str, Any],
                 namespace: Optional[str]) -> None:
        check_node_name(name)
        self.name = name
        self.namespace = normalise_namespace(namespace)
        self._params: dict[str, Any] = read_ros_params(params_file, name) if params_file else {}
        for key, value in overrides.items():
            set_dotted(self._params, key, value)
        self.use_sim_time = self._sim_time_flag(self._params.get("use_sim_time", False))
        self._endpoints: list[Endpoint] = []
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

    def _wake(self) -> None:  # noqa: B027 (a hook, not abstract: a backend that waits with a timeout needs none)
        """Interrupt a blocking wait of the executor (backends that wait without a timeout)."""

    @abc.abstractmethod
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
        value = typed_value(f"{self.name}.{name}", self.param(name, default), default)
        set_dotted(self._params, name, value)
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

    # -- messaging and the executor: what each backend implements -------------------
    @abc.abstractmethod
    def publisher(self, type_name: str, topic: str, qos: Qos = QOS_DEFAULT) -> Publisher:
        """A publisher of ``type_name`` (``pkg/msg/Name``) on ``topic`` (resolved against the node's namespace)."""
        raise NotImplementedError

    @abc.abstractmethod
    def subscription(self, type_name: str, topic: str, callback: Callable[[Any], None],
                     qos: Qos = QOS_DEFAULT, wake: bool = True) -> Handle:
        """``callback`` for each message of ``type_name`` on ``topic``, called from :meth:`spin`/:meth:`spin_once`.
        ``wake=False``: a message on it need not wake the executor; it is taken with the next wake-up's (a message
        on another subscription, a timer) or after :data:`WAKE_POLL` seconds at the latest, still in publication
        order.  A lockstep node's data: the marker that announces them, sent after them, wakes it (rclpy's executor
        waits on every subscription: there it wakes as any other)."""
        raise NotImplementedError

    @abc.abstractmethod
    def timer(self, period: float, callback: Callable[[], None]) -> Handle:
        """``callback`` every ``period`` seconds of the node's clock (simulated time with ``use_sim_time``)."""
        raise NotImplementedError

    def watch(self, fileno: Callable[[], Optional[int]], callback: Callable[[], None], poll: float) -> Handle:
        """``callback`` whenever the file descriptor ``fileno()`` is readable: input the middleware does not carry
        (the CAN bus's socket), called from :meth:`spin`/:meth:`spin_once` like any other callback.  A thread waits
        on the descriptor (``select``) and wakes the executor; it waits again once the callback has run, so data the
        callback leaves unread wakes it again at once, and read data does not.  ``fileno()`` is asked before every
        wait (a reopened bus is watched); while it gives ``None`` (no descriptor, or the bus is closed) the callback
        runs every ``poll`` seconds instead."""
        watch = _Watch(fileno, callback, check_period(poll))
        self._arm(watch)
        thread = threading.Thread(target=watch.run, args=(self._stop, self._fire_watch), name=f"watch-{self.name}",
                                  daemon=True)
        thread.start()
        return Handle(watch.cancel)

    @abc.abstractmethod
    def _arm(self, watch: "_Watch") -> None:
        """Backend: prepare to run ``watch``'s callback in the executor when :meth:`_fire_watch` is called."""
        raise NotImplementedError

    @abc.abstractmethod
    def _fire_watch(self, watch: "_Watch") -> None:
        """Backend, from the watch's thread: run ``watch.done()`` in the executor's thread, soon."""
        raise NotImplementedError

    @abc.abstractmethod
    def now(self) -> float:
        """ROS time (s): simulated time with ``use_sim_time``, else the wall clock."""
        raise NotImplementedError

    @abc.abstractmethod
    def make(self, type_name: str, **fields: Any) -> Any:
        """A message of ``type_name`` of this backend with ``fields`` set (an unknown field is a ``TypeError``)."""
        raise NotImplementedError

    @staticmethod
    @abc.abstractmethod
    def serialize(msg: Any) -> bytes:
        """The message's CDR with its encapsulation header, as rosbag2 stores it."""
        raise NotImplementedError

    @abc.abstractmethod
    def spin_once(self, timeout: float) -> None:
        """Run callbacks and timers for ``timeout`` seconds (returns early on :meth:`shutdown`)."""
        raise NotImplementedError

    @abc.abstractmethod
    def spin_some(self) -> None:
        """Run the callbacks of what has arrived and the timers that are due, without waiting (rclcpp's
        ``spin_some``): a node that reads many topics and need not answer each message at once polls with it."""
        raise NotImplementedError

    @abc.abstractmethod
    def spin(self, until: Optional[Callable[[], bool]] = None) -> None:
        """Run callbacks and timers until :meth:`shutdown` or ``until()`` is true."""
        raise NotImplementedError

    # -- introspection ---------------------------------------------------------------
    @abc.abstractmethod
    def node_names(self) -> list[tuple[str, str]]:
        """(namespace, name) of the other nodes in the graph (``ros2 node list``)."""
        raise NotImplementedError

    @abc.abstractmethod
    def count_publishers(self, topic: str) -> int:
        raise NotImplementedError

    @abc.abstractmethod
    def count_subscribers(self, topic: str) -> int:
        raise NotImplementedError

    @abc.abstractmethod
    def describe_discovery(self) -> str:
        """How far this node's DDS discovery reaches and how that is held (one line for the log)."""
        raise NotImplementedError

    def endpoints(self) -> list[Endpoint]:
        """The publishers and subscriptions this node created (the runtime's ``/clock`` reader included)."""
        return list(self._endpoints)

    def _track(self, kind: str, topic: str, type_name: str, qos: Qos) -> None:
        self._endpoints.append(Endpoint(kind, topic, type_name, qos))

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

