"""Message types for the DDS path, generated from the `.msg` files — never written by hand.

Definitions come from two places only: the ``.msg`` files of ``moose_msgs`` (ours) and
rosbags' bundled ROS 2 Jazzy type store (standard messages).  From these, Cyclone DDS
``IdlStruct`` classes are built at import time with the type names rmw_cyclonedds uses
(``pkg::msg::dds_::Type_``), so their CDR on the wire is what a ROS 2 node sends and
receives.  Instances are plain dataclasses: fields by their ``.msg`` names, defaults
zero/empty, nested messages constructed by default.
"""
from __future__ import annotations

import dataclasses
import os
import re
import types as pytypes
from functools import lru_cache
from pathlib import Path
from typing import Any

from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from moose.resources import package_folder

MSG_PACKAGE = "moose_msgs"


@lru_cache(maxsize=1)
def _base_types() -> dict[str, tuple[Any, Any]]:
    """IDL annotation and default of each base type (Cyclone DDS is imported only when a DDS type is built, so
    the rclpy backend and the bag tools do without it)."""
    import cyclonedds.idl.types as idl

    return {  # byte and char are uint8 on the wire and in rmw_cyclonedds' type information
        "bool": (bool, False), "byte": (idl.uint8, 0), "char": (idl.uint8, 0),
        "int8": (idl.int8, 0), "uint8": (idl.uint8, 0), "int16": (idl.int16, 0), "uint16": (idl.uint16, 0),
        "int32": (idl.int32, 0), "uint32": (idl.uint32, 0), "int64": (idl.int64, 0), "uint64": (idl.uint64, 0),
        "float32": (idl.float32, 0.0), "float64": (idl.float64, 0.0), "string": (str, ""),
    }


class UnknownMessageType(KeyError):
    """A message type name that is malformed or defined nowhere; ``str()`` is the plain message."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


def msg_dir() -> Path:
    """Folder of our ``.msg`` files: ``$MOOSE_MSG_DIR``, else the copy shipped in this package (package data:
    ``moose_ros/msg``, a link to moose_msgs' in the source tree), else moose_msgs' share folder from the ament
    index."""
    env = os.environ.get("MOOSE_MSG_DIR")
    if env:
        return Path(env)
    shipped = package_folder("moose_ros", "msg")
    if any(shipped.glob("*.msg")):
        return shipped
    try:
        from ament_index_python.packages import get_package_share_directory

        return Path(get_package_share_directory(MSG_PACKAGE)) / "msg"
    except Exception:  # noqa: BLE001 - PackageNotFoundError, or no ament_index_python at all
        return shipped


@lru_cache(maxsize=1)
def typestore() -> Any:
    """rosbags type store: ROS 2 Jazzy's standard messages plus ours."""
    store = get_typestore(Stores.ROS2_JAZZY)
    folder = msg_dir()
    files = sorted(folder.glob("*.msg"))
    if not files:
        raise FileNotFoundError(f"no .msg files in {folder}: "
                                "reinstall moose_ros or set MOOSE_MSG_DIR to moose_msgs/msg")
    definitions: dict[str, Any] = {}
    for path in files:
        definitions.update(get_types_from_msg(path.read_text(encoding="utf-8"), f"{MSG_PACKAGE}/msg/{path.stem}"))
    store.register(definitions)
    return store


_TYPE_NAME = re.compile(r"^[a-z][a-z0-9_]*/msg/[A-Z][A-Za-z0-9]*$")


def check_type_name(type_name: str) -> None:
    """Raise :class:`UnknownMessageType` unless ``type_name`` has the form ``pkg/msg/Type``."""
    if not isinstance(type_name, str) or not _TYPE_NAME.match(type_name):
        raise UnknownMessageType(f"message type {type_name!r} is invalid: expected 'package/msg/Type', "
                                 "e.g. 'nav_msgs/msg/Odometry'")


def dds_type_name(type_name: str) -> str:
    """``pkg/msg/Type`` → ``pkg::msg::dds_::Type_`` (rmw_cyclonedds)."""
    check_type_name(type_name)
    pkg, kind, name = type_name.split("/")
    return f"{pkg}::{kind}::dds_::{name}_"


def ros_type_name(dds_name: str) -> str:
    """``pkg::msg::dds_::Type_`` → ``pkg/msg/Type`` (other names are returned unchanged)."""
    parts = dds_name.split("::")
    if len(parts) == 4 and parts[2] == "dds_" and parts[3].endswith("_"):
        return f"{parts[0]}/{parts[1]}/{parts[3][:-1]}"
    return dds_name


def _field_type(node: tuple) -> tuple[Any, Any]:
    """IDL annotation and default factory for a rosbags field node."""
    kind, detail = node
    if kind == Nodetype.BASE:
        base, _bound = detail
        annotation, default = _base_types()[base]
        return annotation, (lambda d=default: d)
    if kind == Nodetype.NAME:
        cls = message_class(detail)
        return cls, cls
    import cyclonedds.idl.types as idl

    element, size = detail
    inner, inner_default = _field_type(element)
    # cyclonedds' array[...] and sequence[...] are __class_getitem__ on plain classes (they build Annotated
    # types), which mypy does not model
    if kind == Nodetype.ARRAY:
        return (idl.array[inner, size],  # type: ignore[misc]
                lambda f=inner_default, n=size: [f() for _ in range(n)])
    return (idl.sequence[inner, size] if size else idl.sequence[inner]), list  # type: ignore[misc]


@lru_cache(maxsize=None)
def message_class(type_name: str) -> type[Any]:
    """The DDS dataclass of ``pkg/msg/Type``; raises :class:`UnknownMessageType` (a KeyError) naming it."""
    from cyclonedds.idl import IdlStruct

    check_type_name(type_name)
    store = typestore()
    if type_name not in store.fielddefs:
        raise UnknownMessageType(f"message type {type_name!r} is unknown (not a standard ROS 2 Jazzy type "
                                 f"nor in {msg_dir()})")
    constants, fields = store.fielddefs[type_name]
    annotations: dict[str, Any] = {}
    defaults: dict[str, Any] = {}
    for name, node in fields:
        annotation, factory = _field_type(node)
        annotations[name] = annotation
        defaults[name] = dataclasses.field(default_factory=factory)

    def body(namespace: dict[str, Any]) -> None:
        namespace["__annotations__"] = annotations
        namespace.update(defaults)

    cls: type[Any] = pytypes.new_class(type_name.split("/")[-1], (IdlStruct,), {"typename": dds_type_name(type_name)},
                                       body)
    cls = dataclasses.dataclass(cls)
    for const_name, _kind, value in constants:
        setattr(cls, const_name, value)
    cls.ros_type = type_name
    from .cdr import install

    install(cls, type_name, store.fielddefs, message_class)  # its CDR compiled (moose_ros.cdr)
    return cls


def type_hash(type_name: str) -> str:
    """The RIHS01 type hash of ``pkg/msg/Type`` (``RIHS01_`` + 64 hex digits), computed by rosbags'
    ``hash_rihs01`` from the definitions of :func:`typestore` (what ROS 2 Jazzy's rosidl computes)."""
    check_type_name(type_name)
    if type_name not in typestore().fielddefs:
        raise UnknownMessageType(f"message type {type_name!r} is unknown (not a standard ROS 2 Jazzy type "
                                 f"nor in {msg_dir()})")
    return str(typestore().hash_rihs01(type_name))


def field_names(type_name: str) -> list[str]:
    """The fields of ``pkg/msg/Type`` in ``.msg`` order."""
    message_class(type_name)
    return [name for name, _node in typestore().fielddefs[type_name][1]]


def make(type_name: str, **fields: Any) -> Any:
    """A message of ``type_name`` with the given fields (others default); unknown fields are a TypeError."""
    cls = message_class(type_name)
    unknown = sorted(set(fields) - set(cls.__dataclass_fields__))
    if unknown:
        raise TypeError(f"{type_name} has no field {unknown[0]!r}; fields: {', '.join(field_names(type_name))}")
    return cls(**fields)


def normalise(msg: Any) -> Any:
    """Turn numpy arrays/scalars, tuples and ``array.array`` in ``msg`` into the plain Python values the DDS
    serialiser takes (the DDS publisher retries with this when a write fails).  Portable node code assigns
    lists to sequences: rclpy's generated classes take lists or ``array.array``, but no numpy array."""
    for name in msg.__dataclass_fields__:
        setattr(msg, name, _plain(getattr(msg, name)))
    return msg


def _plain(value: Any) -> Any:
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return normalise(value)
    if isinstance(value, (list, tuple)) or type(value).__name__ in ("ndarray", "array"):
        return [_plain(v) for v in value]
    if hasattr(value, "item") and type(value).__module__ == "numpy":
        return value.item()
    return value


def to_rosbags(msg: Any) -> Any:
    """The same content as a rosbags message (for ``serialize_cdr`` and bag writing)."""
    store = typestore()
    type_name = type(msg).ros_type
    cls = store.types[type_name]
    _, fields = store.fielddefs[type_name]
    values = {}
    for name, node in fields:
        values[name] = _convert_out(getattr(msg, name), node, store)
    return cls(**values)


def _convert_out(value: Any, node: tuple, store: Any) -> Any:
    import numpy as np

    kind, detail = node
    if kind == Nodetype.BASE:
        return value
    if kind == Nodetype.NAME:
        return to_rosbags(value)
    element, _size = detail
    if element[0] == Nodetype.BASE and element[1][0] != "string":
        dtype = {"bool": np.bool_, "byte": np.uint8, "char": np.uint8}.get(element[1][0], element[1][0])
        return np.array(value, dtype=dtype)
    return [_convert_out(v, element, store) for v in value]


def from_rosbags(msg: Any, type_name: str) -> Any:
    """A DDS message from a rosbags message (bag replay)."""
    store = typestore()
    _, fields = store.fielddefs[type_name]
    values = {}
    for name, node in fields:
        values[name] = _convert_in(getattr(msg, name), node)
    return message_class(type_name)(**values)


def _convert_in(value: Any, node: tuple) -> Any:
    kind, detail = node
    if kind == Nodetype.BASE:
        return value
    if kind == Nodetype.NAME:
        return from_rosbags(value, detail)
    element, _size = detail
    if element[0] == Nodetype.BASE:
        return [v.item() if hasattr(v, "item") else v for v in value]
    return [_convert_in(v, element) for v in value]
