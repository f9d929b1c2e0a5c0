"""The small runtime every node is written against: rclpy when importable, else Cyclone DDS.

API (both backends): ``publisher(type, topic, qos)``, ``subscription(type, topic, cb, qos)``,
``timer(period, cb)``, ``param(name, default)``, ``now()``, ``log_info/warn/error``,
``spin(until)``, ``shutdown()``, ``make(type, **fields)``.  Message objects have the
``.msg`` field names on both backends.

The DDS backend follows rmw_cyclonedds: topic ``/x`` is DDS topic ``rt/x``, type names
``pkg::msg::dds_::Type_``, CDR (XCDR1) encoding, domain from ``ROS_DOMAIN_ID``.  One
thread per node waits on a DDS WaitSet and only enqueues samples (a DDS listener that
takes samples can deadlock against a write from the same participant); callbacks and
timers run in ``spin`` on one thread, like rclpy's single-threaded executor.  With ``use_sim_time`` the clock follows ``/clock``
and timers fire on simulated time.
"""
from __future__ import annotations

import dataclasses
import os
import queue
import sys
import threading
import time
from pathlib import Path
from typing import Any, Callable, Optional

from moose.params import ParamError, read_ros_params

from .interfaces import make as make_dds
from .interfaces import message_class


@dataclasses.dataclass(frozen=True)
class Qos:
    """A ROS 2 QoS profile (the subset the graph uses)."""

    reliable: bool = True
    depth: int = 10
    transient_local: bool = False


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


def _rclpy_available() -> bool:
    if os.environ.get("MOOSE_RUNTIME") == "dds":
        return False
    try:
        import rclpy  # noqa: F401
    except ImportError:
        return False
    return True


class _Timer:
    def __init__(self, period: float, callback: Callable[[], None], start: float) -> None:
        self.period, self.callback, self.next = period, callback, start + period


class _NodeBase:
    """Parameters, logging and clock shared by both backends."""

    def __init__(self, name: str, params_file: Optional[str], overrides: dict[str, Any]) -> None:
        self.name = name
        self._params: dict[str, Any] = read_ros_params(params_file, name) if params_file else {}
        self._params.update(overrides)
        self.use_sim_time = bool(self._params.get("use_sim_time", False))

    def param(self, name: str, default: Any = None) -> Any:
        """Parameter ``name`` (dotted for nested groups), or ``default``."""
        value: Any = self._params
        for part in name.split("."):
            if not isinstance(value, dict) or part not in value:
                return default
            value = value[part]
        return value

    @property
    def parameters(self) -> dict[str, Any]:
        return self._params

    def _log(self, level: str, text: str) -> None:
        print(f"[{level}] [{self.name}] {text}", file=sys.stderr if level != "INFO" else sys.stdout, flush=True)

    def log_info(self, text: str) -> None:
        self._log("INFO", text)

    def log_warn(self, text: str) -> None:
        self._log("WARN", text)

    def log_error(self, text: str) -> None:
        self._log("ERROR", text)


class DdsNode(_NodeBase):
    """A node on Cyclone DDS with ROS 2 wire conventions."""

    def __init__(self, name: str, params_file: Optional[str] = None, overrides: Optional[dict[str, Any]] = None) -> None:
        from cyclonedds.domain import DomainParticipant

        super().__init__(name, params_file, overrides or {})
        domain = int(os.environ.get("ROS_DOMAIN_ID", "0"))
        self.participant = DomainParticipant(domain)
        self._queue: "queue.Queue[tuple[Callable[[Any], None], Any]]" = queue.Queue()
        self._timers: list[_Timer] = []
        self._topics: dict[str, Any] = {}
        self._keep: list[Any] = []
        self._readers: list[tuple[Any, Callable[[Any], None], type, Any]] = []
        self._readers_lock = threading.Lock()
        self._waitset: Any = None
        self._take_thread: Optional[threading.Thread] = None
        self._stop = threading.Event()
        self._sim_now: Optional[float] = None
        if self.use_sim_time:
            self.subscription("rosgraph_msgs/msg/Clock", "/clock", self._on_clock, QOS_CLOCK)

    # -- entities ------------------------------------------------------------
    def _topic(self, type_name: str, topic: str) -> Any:
        from cyclonedds.topic import Topic

        dds_name = "rt/" + topic.lstrip("/")
        cls = message_class(type_name)
        known = self._topics.get(dds_name)
        if known is not None:
            if known.data_type is not cls:
                raise TypeError(f"topic {topic!r} is already used with type {known.data_type.ros_type!r}, not {type_name!r}")
            return known
        made = Topic(self.participant, dds_name, cls)
        self._topics[dds_name] = made
        return made

    @staticmethod
    def _qos(profile: Qos) -> Any:
        from cyclonedds.core import Policy, Qos as DdsQos
        from cyclonedds.util import duration

        return DdsQos(
            Policy.Reliability.Reliable(duration(milliseconds=100)) if profile.reliable else Policy.Reliability.BestEffort,
            Policy.History.KeepLast(profile.depth),
            Policy.Durability.TransientLocal if profile.transient_local else Policy.Durability.Volatile,
        )

    def publisher(self, type_name: str, topic: str, qos: Qos = QOS_DEFAULT) -> Callable[[Any], None]:
        from cyclonedds.pub import DataWriter

        writer = DataWriter(self.participant, self._topic(type_name, topic), qos=self._qos(qos))
        self._keep.append(writer)
        cls = message_class(type_name)

        def publish(msg: Any) -> None:
            if type(msg) is not cls:
                raise TypeError(f"publishing {type(msg).__name__} on {topic!r}, which carries {type_name!r}")
            writer.write(msg)

        return publish

    def subscription(self, type_name: str, topic: str, callback: Callable[[Any], None], qos: Qos = QOS_DEFAULT) -> None:
        from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState, WaitSet
        from cyclonedds.sub import DataReader

        reader = DataReader(self.participant, self._topic(type_name, topic), qos=self._qos(qos))
        if self._waitset is None:
            self._waitset = WaitSet(self.participant)
            self._take_thread = threading.Thread(target=self._take_loop, name=f"{self.name}-dds", daemon=True)
            self._take_thread.start()
        condition = ReadCondition(reader, SampleState.Any | ViewState.Any | InstanceState.Any)
        with self._readers_lock:
            self._readers.append((reader, callback, message_class(type_name), condition))
            self._waitset.attach(condition)

    def _take_loop(self) -> None:
        """Wait on all readers and hand samples to the executor (never calls back inside DDS)."""
        from cyclonedds.util import duration

        while not self._stop.is_set():
            self._waitset.wait(duration(milliseconds=50))
            with self._readers_lock:
                readers = list(self._readers)
            for reader, callback, cls, _ in readers:
                for sample in reader.take(N=256):
                    if isinstance(sample, cls):  # skip dispose/unregister notifications
                        self._queue.put((callback, sample))

    def timer(self, period: float, callback: Callable[[], None]) -> None:
        self._timers.append(_Timer(period, callback, self.now()))

    # -- time --------------------------------------------------------------------
    def _on_clock(self, msg: Any) -> None:
        self._sim_now = msg.clock.sec + 1e-9 * msg.clock.nanosec

    def now(self) -> float:
        if self.use_sim_time:
            return self._sim_now if self._sim_now is not None else 0.0
        return time.time()

    @staticmethod
    def make(type_name: str, **fields: Any) -> Any:
        return make_dds(type_name, **fields)

    # -- executor ----------------------------------------------------------------
    def spin_once(self, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while True:
            remaining = deadline - time.monotonic()
            try:
                callback, sample = self._queue.get(timeout=max(remaining, 0.0)) if remaining > 0 else self._queue.get_nowait()
            except queue.Empty:
                break
            callback(sample)
            self._fire_timers()
        self._fire_timers()

    def _fire_timers(self) -> None:
        now = self.now()
        if self.use_sim_time and self._sim_now is None:
            return
        for timer in self._timers:
            if now + 1e-9 >= timer.next:
                timer.next = max(timer.next + timer.period, now) if now - timer.next > timer.period else timer.next + timer.period
                timer.callback()

    def spin(self, until: Optional[Callable[[], bool]] = None) -> None:
        """Run callbacks and timers until ``shutdown`` or ``until()`` is true."""
        while not self._stop.is_set() and not (until and until()):
            if self._timers and not self.use_sim_time:
                wait = max(0.0, min(t.next for t in self._timers) - self.now())
            else:
                wait = 0.05
            self.spin_once(min(wait, 0.05))

    def shutdown(self) -> None:
        """Stop spinning; the DDS intake thread leaves its wait within 50 ms and is joined."""
        self._stop.set()
        thread = self._take_thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=2.0)


class RclpyNode(_NodeBase):
    """The same API on rclpy (ROS 2 installed): generated message classes, real executor."""

    def __init__(self, name: str, params_file: Optional[str] = None, overrides: Optional[dict[str, Any]] = None) -> None:
        import rclpy
        from rclpy.node import Node

        super().__init__(name, params_file, overrides or {})
        if not rclpy.ok():
            args = ["--ros-args", "--params-file", params_file] if params_file else None
            rclpy.init(args=args)
        self._rclpy = rclpy
        self.node = Node(name, automatically_declare_parameters_from_overrides=True)
        for dotted, parameter in self.node.get_parameters_by_prefix("").items():
            target = self._params
            *groups, leaf = dotted.split(".")
            for group in groups:
                target = target.setdefault(group, {})
            target[leaf] = parameter.value
        if self.node.has_parameter("use_sim_time"):
            self.use_sim_time = bool(self.node.get_parameter("use_sim_time").value)
        self._stop = False

    @staticmethod
    def _class(type_name: str) -> Any:
        import importlib

        pkg, kind, name = type_name.split("/")
        return getattr(importlib.import_module(f"{pkg}.{kind}"), name)

    @staticmethod
    def _qos(profile: Qos) -> Any:
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

        return QoSProfile(
            history=HistoryPolicy.KEEP_LAST, depth=profile.depth,
            reliability=ReliabilityPolicy.RELIABLE if profile.reliable else ReliabilityPolicy.BEST_EFFORT,
            durability=DurabilityPolicy.TRANSIENT_LOCAL if profile.transient_local else DurabilityPolicy.VOLATILE,
        )

    def publisher(self, type_name: str, topic: str, qos: Qos = QOS_DEFAULT) -> Callable[[Any], None]:
        return self.node.create_publisher(self._class(type_name), topic, self._qos(qos)).publish

    def subscription(self, type_name: str, topic: str, callback: Callable[[Any], None], qos: Qos = QOS_DEFAULT) -> None:
        self.node.create_subscription(self._class(type_name), topic, callback, self._qos(qos))

    def timer(self, period: float, callback: Callable[[], None]) -> None:
        self.node.create_timer(period, callback)

    def now(self) -> float:
        return self.node.get_clock().now().nanoseconds * 1e-9

    def make(self, type_name: str, **fields: Any) -> Any:
        msg = self._class(type_name)()
        for key, value in fields.items():
            setattr(msg, key, value)
        return msg

    def log_info(self, text: str) -> None:
        self.node.get_logger().info(text)

    def log_warn(self, text: str) -> None:
        self.node.get_logger().warning(text)

    def log_error(self, text: str) -> None:
        self.node.get_logger().error(text)

    def spin(self, until: Optional[Callable[[], bool]] = None) -> None:
        while self._rclpy.ok() and not self._stop and not (until and until()):
            self._rclpy.spin_once(self.node, timeout_sec=0.05)

    def shutdown(self) -> None:
        self._stop = True


def create_node(name: str, params_file: Optional[str] = None, overrides: Optional[dict[str, Any]] = None) -> Any:
    """A node on rclpy when it is importable (and MOOSE_RUNTIME is not ``dds``), else on Cyclone DDS."""
    if params_file is not None and not Path(params_file).is_file():
        raise ParamError(f"--params {params_file!r}: no such file")
    cls = RclpyNode if _rclpy_available() else DdsNode
    return cls(name, params_file, overrides)
