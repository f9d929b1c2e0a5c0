"""The small runtime every node is written against: rclpy (a real ROS 2 node) or Cyclone DDS with
ROS 2's wire conventions.

Which one (:func:`backend`): ``MOOSE_RUNTIME=rclpy`` or ``MOOSE_RUNTIME=dds``; unset, rclpy when this
interpreter can import both ``rclpy`` and ``moose_msgs`` (a sourced ROS 2 workspace, or ``.venv-ros``
of ``make ros``), else Cyclone DDS.  A process on another runtime than this one's (``moose launch
--runtime``) is started by :func:`process`.

API (both backends, see :class:`NodeBase`):

- ``create_node(name, params_file=None, overrides=None, namespace=None, runtime=None)``
- ``publisher(type, topic, qos)`` → :class:`Publisher` (call it with a message, or ``.publish(msg)``)
- ``subscription(type, topic, callback, qos)``, ``timer(period, callback)``, ``watch(fileno, callback, poll)`` (a
  file descriptor's data, e.g. the CAN bus) → handles with ``cancel()``
- ``declare_parameter(name, default)``, ``get_parameter(name)``, ``param(name, default)``, ``parameters``
- ``now()`` (s; simulated time when ``use_sim_time``), ``log_info/log_warn/log_error``
- ``count_publishers(topic)``, ``count_subscribers(topic)`` (graph introspection), ``endpoints()`` (its own)
- ``spin(until)``, ``spin_once(timeout)``, ``spin_some()`` (what has arrived, without waiting), ``shutdown()``,
  ``make(type, **fields)``, ``serialize(msg)``

Both executors are single-threaded and run the callbacks of the messages they take at once in
publication order (source timestamps), then the timers that are due.

Message types are named ``pkg/msg/Type``; message objects have the ``.msg`` field names on both
backends (generated rclpy classes, or the DDS dataclasses of :mod:`moose_ros.interfaces`).

Modules: :mod:`.qos` (profiles), :mod:`.names` (ROS 2 names), :mod:`.base` (the node base class:
parameters, logging, life cycle), :mod:`.discovery` (how far DDS discovery reaches: this host by
default, ``ROS_AUTOMATIC_DISCOVERY_RANGE`` to opt in), :mod:`.dds` (the Cyclone DDS backend with
rmw_cyclonedds' wire conventions and its executor), :mod:`.rclpy_node` (the rclpy backend).  The backends import their
middleware only when a node is created.
"""
from __future__ import annotations

import importlib
import json
import os
import sys
from pathlib import Path
from typing import Any, Mapping, Optional

from moose.params import ParamError

from .base import Endpoint, Handle, NodeBase, Publisher
from .dds import DdsNode
from .names import CLOCK_TOPIC, CLOCK_TYPE, dds_topic_name, normalise_namespace, resolve_topic
from .qos import QOS_CLOCK, QOS_CLOCK_READER, QOS_DEFAULT, QOS_LATCHED, QOS_LATCHED_READER, QOS_SENSOR, Qos
from .rclpy_node import RclpyNode

__all__ = [
    "CLOCK_TOPIC", "CLOCK_TYPE", "QOS_CLOCK", "QOS_CLOCK_READER", "QOS_DEFAULT", "QOS_LATCHED", "QOS_LATCHED_READER",
    "QOS_SENSOR", "RUNTIMES", "DdsNode", "Endpoint", "Handle", "NodeBase", "Publisher", "Qos", "RclpyNode", "backend",
    "create_node", "dds_topic_name", "normalise_namespace", "prefix_environment", "process", "rclpy_missing",
    "resolve_topic", "ros_prefix",
]


RUNTIMES = ("rclpy", "dds")
"""The runtimes: a real ROS 2 node (rclpy, with the RMW of the ROS installation), or Cyclone DDS."""

PREFIX_ENV_FILE = "ros-env.json"
"""The environment of a ROS 2 prefix made by ``make ros`` (``ros2_ws/ros_prefix.py`` writes it)."""


def _choice(runtime: Optional[str]) -> str:
    choice = (os.environ.get("MOOSE_RUNTIME", "") if runtime is None else runtime).strip().lower()
    if choice not in ("", *RUNTIMES):
        what = "MOOSE_RUNTIME" if runtime is None else "runtime"
        raise ParamError(f"{what} = {choice!r} is invalid: expected one of {', '.join(map(repr, RUNTIMES))}")
    return choice


def rclpy_missing() -> str:
    """Why this interpreter cannot run nodes on rclpy (``""`` if it can): ``rclpy`` or ``moose_msgs`` (the
    generated messages, built by ``make ros`` or ``colcon build``) is not importable."""
    for module in ("rclpy", "moose_msgs.msg"):
        try:
            importlib.import_module(module)
        except ImportError as exc:
            return f"{module.split('.')[0]} cannot be imported ({exc})"
    return ""


def backend(runtime: Optional[str] = None) -> str:
    """The runtime of a node of this process: ``runtime`` or ``$MOOSE_RUNTIME`` if given (``rclpy`` or
    ``dds``; ``rclpy`` that cannot be imported is a :class:`ParamError` saying why), else ``rclpy`` when
    both ``rclpy`` and ``moose_msgs`` can be imported, else ``dds``."""
    choice = _choice(runtime)
    if choice == "dds":
        return "dds"
    missing = rclpy_missing()
    if missing and choice == "rclpy":
        raise ParamError(f"runtime 'rclpy' is not available in {sys.executable}: {missing}; run `make ros` and use "
                         "its interpreter (. .venv-ros/setup.sh), or source a ROS 2 workspace with moose_msgs")
    return "dds" if missing else "rclpy"


def ros_prefix() -> Optional[Path]:
    """The ROS 2 prefix of ``make ros``: ``$MOOSE_ROS_PREFIX``, else ``.venv-ros`` of the checkout this
    package runs from; ``None`` when that has no environment file (not made)."""
    checkout = Path(__file__).resolve().parents[5]
    prefix = Path(os.environ.get("MOOSE_ROS_PREFIX") or checkout / ".venv-ros")
    return prefix if (prefix / PREFIX_ENV_FILE).is_file() else None


def prefix_environment(prefix: Path, base: Mapping[str, str]) -> dict[str, str]:
    """``base`` with the variables of ``PREFIX/ros-env.json`` set and prepended (its format:
    ``ros2_ws/ros_prefix.py``, ``spec``; ``tests/test_rclpy_runtime.py`` checks that both agree)."""
    values = json.loads((prefix / PREFIX_ENV_FILE).read_text(encoding="utf-8"))
    env = dict(base)
    env.update(values["set"])
    for name, parts in values["prepend"].items():
        env[name] = os.pathsep.join(parts + ([env[name]] if env.get(name) else []))
    return env


def process(runtime: Optional[str] = None, base: Optional[Mapping[str, str]] = None) -> tuple[str, dict[str, str]]:
    """Interpreter and environment of a child process whose nodes run on ``runtime`` (default: this
    process's :func:`backend`), with ``MOOSE_RUNTIME`` set so that the child cannot fall back silently.

    ``dds``, or ``rclpy`` when this interpreter can run it: this interpreter and ``base`` (default
    ``os.environ``).  ``rclpy`` otherwise: the interpreter and environment of the ROS 2 prefix
    (:func:`ros_prefix`); none is a :class:`ParamError`."""
    env = dict(os.environ if base is None else base)
    chosen = _choice(runtime) or backend()
    if chosen == "rclpy" and rclpy_missing():
        prefix = ros_prefix()
        if prefix is None:
            raise ParamError(f"runtime 'rclpy': {rclpy_missing()} in {sys.executable}, and no ROS 2 prefix "
                             f"(MOOSE_ROS_PREFIX, or .venv-ros of this checkout) has {PREFIX_ENV_FILE}: run `make ros`")
        env = prefix_environment(prefix, env)
        return env["MOOSE_ROS_PYTHON"], {**env, "MOOSE_RUNTIME": "rclpy"}
    return sys.executable, {**env, "MOOSE_RUNTIME": chosen}


def create_node(name: str, params_file: Optional[str] = None, overrides: Optional[dict[str, Any]] = None,
                namespace: Optional[str] = None, runtime: Optional[str] = None) -> NodeBase:
    """A node on ``runtime`` (default: :func:`backend`, from ``MOOSE_RUNTIME`` or what is importable).

    ``params_file``: a ROS 2 parameter YAML (``/**`` and the node's own section); ``overrides``:
    ``{dotted.name: value}`` applied on top.  A missing or malformed file is a :class:`ParamError`.
    """
    if params_file is not None and not Path(params_file).is_file():
        raise ParamError(f"--params {params_file!r}: no such file")
    cls = RclpyNode if backend(runtime) == "rclpy" else DdsNode
    return cls(name, params_file, overrides, namespace)
