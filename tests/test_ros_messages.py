"""The DDS path's CDR equals rosbags' serialize_cdr for every message type the graph uses."""
from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from rosbags.interfaces import Nodetype

from moose_ros.interfaces import dds_type_name, from_rosbags, make, message_class, msg_dir, to_rosbags, typestore

OURS = sorted(f"moose_msgs/msg/{p.stem}" for p in msg_dir().glob("*.msg"))
STANDARD = ["nav_msgs/msg/Odometry", "sensor_msgs/msg/Imu", "diagnostic_msgs/msg/DiagnosticArray",
            "rosgraph_msgs/msg/Clock", "std_msgs/msg/Header"]


def fill(type_name: str, seed: int) -> Any:
    """A message with non-trivial content: odd-length strings, 3-element sequences, distinct numbers."""
    store = typestore()
    msg = message_class(type_name)()
    for i, (name, node) in enumerate(store.fielddefs[type_name][1]):
        setattr(msg, name, value(node, seed + 7 * i))
    return msg


def value(node: tuple, seed: int) -> Any:
    kind, detail = node
    if kind == Nodetype.BASE:
        base = detail[0]
        if base == "string":
            return "ab" * (seed % 4) + "x"
        if base == "bool":
            return seed % 2 == 0
        if base.startswith("float"):
            return seed * 0.5 + 0.25
        return seed % 100 + (1 if not base.startswith("u") and base not in ("byte", "char") else 0)
    if kind == Nodetype.NAME:
        return fill(detail, seed)
    element, size = detail
    return [value(element, seed + k) for k in range(size or 3)]


def test_every_custom_message_is_defined() -> None:
    assert set(OURS) >= {f"moose_msgs/msg/{n}" for n in (
        "ActuatorCommand", "Blend", "Obstacle", "ObstacleArray", "PlannerOutput", "Reference", "StateEstimate",
        "SteeringReport", "Threat", "WheelSpeeds")}


@pytest.mark.parametrize("type_name", OURS + STANDARD)
def test_cdr_is_byte_identical_to_rosbags(type_name: str) -> None:
    msg = fill(type_name, 3)
    wire = bytes(msg.serialize())
    reference = bytes(typestore().serialize_cdr(to_rosbags(msg), type_name))
    assert wire[:4] == b"\x00\x01\x00\x00"  # CDR little endian, as rmw_cyclonedds
    assert wire == reference
    back = from_rosbags(typestore().deserialize_cdr(reference, type_name), type_name)
    assert bytes(back.serialize()) == wire


def test_type_names_follow_rmw_cyclonedds() -> None:
    assert message_class("nav_msgs/msg/Odometry").__idl_typename__ == "nav_msgs::msg::dds_::Odometry_"
    assert dds_type_name("moose_msgs/msg/Threat") == "moose_msgs::msg::dds_::Threat_"
    assert message_class("moose_msgs/msg/PlannerOutput").STATUS_OVER_BUDGET == 3


def test_unknown_type_is_a_clear_error() -> None:
    with pytest.raises(KeyError, match="moose_msgs/msg/Nope"):
        make("moose_msgs/msg/Nope")


def test_fixed_arrays_have_their_size() -> None:
    imu = make("sensor_msgs/msg/Imu")
    assert len(imu.orientation_covariance) == 9
    assert np.asarray(to_rosbags(imu).orientation_covariance).shape == (9,)
