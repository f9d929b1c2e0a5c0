"""The small runtime every node is written against: rclpy when importable, else Cyclone DDS.

API (both backends, see :class:`NodeBase`):

- ``create_node(name, params_file=None, overrides=None, namespace=None)``
- ``publisher(type, topic, qos)`` → :class:`Publisher` (call it with a message, or ``.publish(msg)``)
- ``subscription(type, topic, callback, qos)``, ``timer(period, callback)`` → handles with ``cancel()``
- ``declare_parameter(name, default)``, ``get_parameter(name)``, ``param(name, default)``, ``parameters``
- ``now()`` (s; simulated time when ``use_sim_time``), ``log_info/log_warn/log_error``
- ``count_publishers(topic)``, ``count_subscribers(topic)`` (graph introspection), ``endpoints()`` (its own)
- ``spin(until)``, ``spin_once(timeout)``, ``shutdown()``, ``make(type, **fields)``

Message types are named ``pkg/msg/Type``; message objects have the ``.msg`` field names on both
backends (generated rclpy classes, or the DDS dataclasses of :mod:`moose_ros.interfaces`).

Modules: :mod:`.qos` (profiles), :mod:`.names` (ROS 2 names), :mod:`.base` (the node base class:
parameters, logging, life cycle), :mod:`.discovery` (how far DDS discovery reaches: this host by
default, ``ROS_AUTOMATIC_DISCOVERY_RANGE`` to opt in), :mod:`.dds` (the Cyclone DDS backend with
rmw_cyclonedds' wire conventions and its executor), :mod:`.rclpy_node` (the rclpy backend).  The backends import their
middleware only when a node is created.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Optional

from moose.params import ParamError

from .base import Endpoint, Handle, NodeBase, Publisher
from .dds import DdsNode
from .names import CLOCK_TOPIC, CLOCK_TYPE, dds_topic_name, normalise_namespace, resolve_topic
from .qos import QOS_CLOCK, QOS_CLOCK_READER, QOS_DEFAULT, QOS_LATCHED, QOS_LATCHED_READER, QOS_SENSOR, Qos
from .rclpy_node import RclpyNode

__all__ = [
    "CLOCK_TOPIC", "CLOCK_TYPE", "QOS_CLOCK", "QOS_CLOCK_READER", "QOS_DEFAULT", "QOS_LATCHED", "QOS_LATCHED_READER",
    "QOS_SENSOR", "DdsNode", "Endpoint", "Handle", "NodeBase", "Publisher", "Qos", "RclpyNode", "backend", "create_node",
    "dds_topic_name", "normalise_namespace", "resolve_topic",
]


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
