"""The compiled CDR of the DDS message classes (moose_ros.cdr) is cyclonedds-python's, byte for byte and value for
value, on every message type of the store, and a message it cannot write fails as cyclonedds-python's does.

Three implementations meet here: the compiled code, cyclonedds-python's interpreter of the type (``IdlStruct``'s own
``serialize`` and ``deserialize``, which the compiled code replaces on our classes) and rosbags' ``serialize_cdr``."""
from __future__ import annotations

import random
import struct
from typing import Any

import pytest
from cyclonedds.idl import IdlStruct
from cyclonedds.idl._support import Endianness
from rosbags.interfaces import Nodetype

from moose_ros.cdr import HEADER
from moose_ros.interfaces import message_class, to_rosbags, typestore

TYPES = sorted(typestore().fielddefs)
INTEGERS = {"int8": 8, "int16": 16, "int32": 32, "int64": 64}


def value(node: tuple[Any, Any], rng: random.Random) -> Any:
    """A random value of a field: full integer ranges, unicode strings, sequences of 0..4 (within their bound)."""
    kind, detail = node
    if kind == Nodetype.BASE:
        base, bound = detail
        if base == "string":
            return "".join(rng.choice("aé€x🦌 ") for _ in range(rng.randint(0, min(bound or 9, 9))))
        if base == "bool":
            return rng.random() < 0.5
        if base == "float32":
            return struct.unpack("<f", struct.pack("<f", rng.uniform(-1e3, 1e3)))[0]
        if base == "float64":
            return rng.uniform(-1e6, 1e6)
        if base == "byte":  # an octet; rosbags writes it signed
            return rng.randint(0, 127)
        if base in INTEGERS:
            return rng.randint(-2 ** (INTEGERS[base] - 1), 2 ** (INTEGERS[base] - 1) - 1)
        return rng.randint(0, 2 ** INTEGERS["int" + base[len("uint"):]] - 1 if base != "char" else 255)
    if kind == Nodetype.NAME:
        return instance(detail, rng)
    element, size = detail
    count = size if kind == Nodetype.ARRAY else rng.randint(0, min(size or 4, 4))
    return [value(element, rng) for _ in range(count)]


def instance(type_name: str, rng: random.Random) -> Any:
    return message_class(type_name)(**{name: value(node, rng) for name, node in typestore().fielddefs[type_name][1]})


def slow(msg: Any) -> bytes:
    return bytes(IdlStruct.serialize(msg))


def slow_read(type_name: str, data: bytes) -> Any:
    return IdlStruct.deserialize.__func__(message_class(type_name), data)  # type: ignore[attr-defined]


@pytest.mark.parametrize("type_name", TYPES)
def test_compiled_cdr_is_cyclonedds_and_rosbags_on_every_type(type_name: str) -> None:
    rng = random.Random(type_name)
    for _ in range(4):
        msg = instance(type_name, rng)
        data = bytes(msg.serialize())
        assert data[:4] == HEADER
        assert data == slow(msg)
        ours = bytes(typestore().serialize_cdr(to_rosbags(msg), type_name))
        assert ours[:len(data)] == data and not ours[len(data):].strip(b"\0")  # rosbags pads to 4 bytes
        read = type(msg).deserialize(data)
        assert type(read) is type(msg) and repr(read) == repr(slow_read(type_name, data))
        assert bytes(read.serialize()) == data


def test_the_classes_carry_the_compiled_code() -> None:
    """Not cyclonedds-python's own functions, which the comparison above would pass too (the speed-up:
    ``python bench/bench_cdr.py``)."""
    cls = message_class("nav_msgs/msg/Odometry")
    assert cls.serialize is not IdlStruct.serialize
    assert cls.serialize.__module__ == cls.deserialize.__func__.__module__ == "moose_ros.cdr"


@pytest.mark.parametrize("case", ["sequence over its bound", "array of the wrong length", "text in a number",
                                  "integer out of range", "float in an integer"])
def test_what_the_compiled_code_cannot_write_fails_as_cyclonedds_does(case: str) -> None:
    rng = random.Random(1)
    if case == "sequence over its bound":
        msg = instance("shape_msgs/msg/SolidPrimitive", rng)
        msg.dimensions = [1.0, 2.0, 3.0, 4.0]
    elif case == "array of the wrong length":
        msg = instance("nav_msgs/msg/Odometry", rng)
        msg.pose.covariance = [0.0] * 35
    else:
        msg = instance("moose_msgs/msg/ActuatorCommand", rng)
        field = next(name for name, node in typestore().fielddefs["moose_msgs/msg/ActuatorCommand"][1]
                     if node == (Nodetype.BASE, ("float64", 0)))
        setattr(msg, field, "fast")
        if case != "text in a number":
            msg = instance("builtin_interfaces/msg/Time", rng)
            msg.sec = 2 ** 40 if case == "integer out of range" else 1.5
    with pytest.raises(Exception) as theirs:
        slow(msg)
    with pytest.raises(type(theirs.value)) as ours:
        msg.serialize()
    assert str(ours.value) == str(theirs.value)


def test_data_the_compiled_code_does_not_read_is_read_by_cyclonedds() -> None:
    """Big-endian and XCDR2 data (another writer's choice) and XCDR2 writing go to cyclonedds-python's code."""
    msg = instance("nav_msgs/msg/Odometry", random.Random(2))
    cls = type(msg)
    big = bytes(msg.serialize(endianness=Endianness.Big))
    assert big[:2] == b"\x00\x00" and big == bytes(IdlStruct.serialize(msg, endianness=Endianness.Big))
    assert repr(cls.deserialize(big)) == repr(msg)
    two = bytes(msg.serialize(use_version_2=True))
    assert two[:2] != HEADER[:2] and two == bytes(IdlStruct.serialize(msg, use_version_2=True))
    assert repr(cls.deserialize(two)) == repr(msg)
