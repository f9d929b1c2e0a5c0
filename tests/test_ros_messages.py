"""The DDS path's CDR equals rosbags' serialize_cdr for every message type the graph uses."""
from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.interfaces import Nodetype

from moose_ros.interfaces import dds_type_name, from_rosbags, make, message_class, msg_dir, to_rosbags, typestore

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "ros2_ws" / "src" / "moose_msgs"
OURS = sorted(f"moose_msgs/msg/{p.stem}" for p in msg_dir().glob("*.msg"))
STANDARD = ["nav_msgs/msg/Odometry", "sensor_msgs/msg/Imu", "diagnostic_msgs/msg/DiagnosticArray",
            "diagnostic_msgs/msg/DiagnosticStatus", "diagnostic_msgs/msg/KeyValue",
            "rosgraph_msgs/msg/Clock", "std_msgs/msg/Header", "builtin_interfaces/msg/Time",
            "geometry_msgs/msg/PoseWithCovariance", "geometry_msgs/msg/TwistWithCovariance",
            "rmw_dds_common/msg/ParticipantEntitiesInfo", "rmw_dds_common/msg/NodeEntitiesInfo",
            "rmw_dds_common/msg/Gid", "tf2_msgs/msg/TFMessage", "geometry_msgs/msg/TransformStamped",
            "visualization_msgs/msg/MarkerArray", "visualization_msgs/msg/Marker", "geometry_msgs/msg/Point"]


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


def test_every_plan_status_has_one_code_on_the_wire_defined_by_the_message() -> None:
    """The STATUS_* constants of PlannerOutput.msg are the one definition: every PlanStatus has one, the codes are
    the message class's, and each round-trips (``barrier_violated`` included)."""
    from types import SimpleNamespace
    from typing import get_args

    from moose.signals import PlanResult, PlanStatus
    from moose_ros import convert as cv

    codes = cv.status_codes()
    cls = message_class("moose_msgs/msg/PlannerOutput")
    assert set(codes) == set(get_args(PlanStatus)) and len(set(codes.values())) == len(codes)
    assert codes == {name: getattr(cls, f"STATUS_{name.upper()}") for name in get_args(PlanStatus)}
    assert codes["barrier_violated"] == cls.STATUS_BARRIER_VIOLATED == 6
    node = SimpleNamespace(make=make)
    for name in get_args(PlanStatus):
        plan = PlanResult(np.zeros((3, 2)), name, 1, 0.0, 1.0, np.zeros((4, 4)))
        assert cv.plan_from_msg(cv.plan_to_msg(node, 0.0, "mpc", plan, True)).status == name


def test_unknown_type_is_a_clear_error() -> None:
    with pytest.raises(KeyError, match="moose_msgs/msg/Nope"):
        make("moose_msgs/msg/Nope")


def test_fixed_arrays_have_their_size() -> None:
    imu = make("sensor_msgs/msg/Imu")
    assert len(imu.orientation_covariance) == 9
    assert np.asarray(to_rosbags(imu).orientation_covariance).shape == (9,)


def test_every_type_the_code_names_is_covered_by_the_cdr_test() -> None:
    """A type used anywhere in the runtime, nodes, bags or core must be in the byte-equality test above."""
    used: set[str] = set()
    for folder in (ROOT / "ros2_ws" / "src" / "moose_ros", ROOT / "src" / "moose"):
        for path in folder.rglob("*.py"):
            used |= set(re.findall(r"[\"']([a-z_]+/msg/[A-Z][A-Za-z0-9]*)[\"']", path.read_text(encoding="utf-8")))
    assert {"nav_msgs/msg/Odometry", "moose_msgs/msg/Threat"} <= used  # the scan finds what it should
    assert used - {"package/msg/Type"} <= set(OURS + STANDARD)  # minus the format example in error texts


def test_package_builds_every_msg_file_with_declared_dependencies() -> None:
    """CMakeLists lists exactly the .msg files; every package a .msg refers to is a dependency in
    package.xml and CMakeLists; names follow rosidl's rules (else rosidl_generate_interfaces fails)."""
    files = sorted(p.name for p in (PKG / "msg").glob("*.msg"))
    cmake = (PKG / "CMakeLists.txt").read_text()
    assert sorted(re.findall(r'"msg/(\w+\.msg)"', cmake)) == files
    xml = ET.parse(PKG / "package.xml").getroot()
    assert xml.findtext("name") == "moose_msgs"
    depends = {e.text for e in xml.findall("depend")} | {e.text for e in xml.findall("build_depend")}
    assert {"builtin_interfaces", "std_msgs", "geometry_msgs", "nav_msgs"} <= depends
    assert xml.findtext("member_of_group") == "rosidl_interface_packages"
    cmake_deps = set(re.search(r"DEPENDENCIES([^)]*)\)", cmake).group(1).split())
    builtin = {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32", "uint32",
               "int64", "uint64", "string", "wstring"}
    for path in (PKG / "msg").glob("*.msg"):
        assert re.match(r"^[A-Z][A-Za-z0-9]*$", path.stem)
        for line in path.read_text().splitlines():
            line = line.split("#", 1)[0].strip()
            if not line:
                continue
            ftype, rest = line.split(None, 1)
            base = re.sub(r"(\[\d*\]|\[<=\d+\])$", "", ftype)
            if "=" in rest:  # constant
                assert re.match(r"^[A-Z]([A-Z0-9_]*[A-Z0-9])?$", rest.split("=")[0].strip()), line
                continue
            name = rest.split()[0]
            assert re.match(r"^(?!.*__)(?!.*_$)[a-z][a-z0-9_]*$", name), line
            if base not in builtin and "/" in base:
                package = base.split("/")[0]
                assert package in depends and package in cmake_deps, f"{path.name}: {package} is not a dependency"
            elif base not in builtin:
                assert (PKG / "msg" / f"{base}.msg").is_file(), f"{path.name}: {base} is not defined"


def test_make_names_unknown_fields_and_publish_values_normalise() -> None:
    with pytest.raises(TypeError, match="moose_msgs/msg/WheelSpeeds has no field 'omega'"):
        make("moose_msgs/msg/WheelSpeeds", omega=1.0)
    with pytest.raises(KeyError, match="expected 'package/msg/Type'"):
        make("Odometry")
    from moose_ros.interfaces import normalise

    msg = make("moose_msgs/msg/PlannerOutput", accel_x=np.arange(3.0), iterations=np.uint32(7), cost=np.float64(2.5))
    normalise(msg)
    assert msg.accel_x == [0.0, 1.0, 2.0] and type(msg.iterations) is int and type(msg.cost) is float
    assert bytes(msg.serialize()) == bytes(typestore().serialize_cdr(to_rosbags(msg), "moose_msgs/msg/PlannerOutput"))


def test_core_records_survive_their_messages() -> None:
    """What a node publishes is what the next node computes with: every field of the core's records goes
    through its message unchanged (the weight function's ρ needs the MPC plan's predicted velocities)."""
    from types import SimpleNamespace

    import numpy as np

    from moose.signals import Obstacle, PlanResult, StateEstimate, Threat
    from moose_ros import convert as cv
    from moose_ros.interfaces import make

    node = SimpleNamespace(make=make)
    rng = np.random.default_rng(0)
    plan = PlanResult(accel=rng.normal(size=(10, 2)), status="capped", iterations=7, solve_time_s=0.001, cost=3.5,
                      predicted=rng.normal(size=(11, 4)))
    msg = cv.plan_to_msg(node, 1.25, "mpc", plan, True)
    assert msg.with_threat is True
    back = cv.plan_from_msg(msg)
    np.testing.assert_array_equal(back.accel, plan.accel)
    np.testing.assert_array_equal(back.predicted, plan.predicted)
    assert (back.status, back.iterations, back.solve_time_s, back.cost) == ("capped", 7, 0.001, 3.5)
    estimate = StateEstimate(1.25, 1.0, -2.0, 0.1, 6.0, 0.2, 0.3, 0.05)
    assert cv.estimate_from_msg(cv.estimate_to_msg(node, estimate)) == estimate
    threat = Threat(1.25, Obstacle(19.0, 21.0, -2.0, 2.4), 3.0, 2.4, 0.23, 1, 0.1)
    assert cv.threat_from_msg(cv.threat_to_msg(node, 1.25, threat)) == threat
