"""What ROS 2 viewers draw: the TF and marker conversions (REP-105 frames), checked against the core's records
and read back through rosbags' CDR (an independent serialiser)."""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from moose.planner.kinematics import kinematic_rollout
from moose.planner.step import blend_path
from moose.signals import Blend, Obstacle, PlanResult, StateEstimate, Threat
from moose_ros import convert as cv
from moose_ros.graph import FRAME_BASE, FRAME_ODOM, FRAME_TRUTH, SENSOR_MOUNTS
from moose_ros.interfaces import make, typestore

NODE = SimpleNamespace(make=make)


def _round_trip(msg):  # type: ignore[no-untyped-def]
    """The message as an independent reader decodes it (rosbags' CDR)."""
    type_name = type(msg).ros_type
    return typestore().deserialize_cdr(bytes(msg.serialize()), type_name)


def _yaw(q) -> float:  # type: ignore[no-untyped-def]
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def test_estimate_and_truth_are_two_children_of_odom() -> None:
    e = StateEstimate(3.25, 10.0, -1.5, 0.3, 7.0, 0.1, 0.2, 0.05)
    tf = _round_trip(cv.estimate_tf(NODE, e)).transforms
    assert [(x.header.frame_id, x.child_frame_id) for x in tf] == [(FRAME_ODOM, FRAME_BASE)]
    assert (tf[0].header.stamp.sec, tf[0].header.stamp.nanosec) == (3, 250_000_000)
    assert (tf[0].transform.translation.x, tf[0].transform.translation.y) == (10.0, -1.5)
    assert _yaw(tf[0].transform.rotation) == pytest.approx(0.3)
    truth = _round_trip(cv.truth_tf(NODE, 3.25, np.array([10.5, -1.0, -2.9, 7.0, 0.0, 0.0]))).transforms
    assert [(x.header.frame_id, x.child_frame_id) for x in truth] == [(FRAME_ODOM, FRAME_TRUTH)]
    assert _yaw(truth[0].transform.rotation) == pytest.approx(-2.9)
    odom = _round_trip(cv.odometry_to_msg(NODE, 3.25, np.array([10.5, -1.0, -2.9, 7.0, 0.0, 0.0])))
    assert (odom.header.frame_id, odom.child_frame_id) == (FRAME_ODOM, FRAME_TRUTH)  # the same body as the TF


def test_static_transforms_put_each_sensor_at_its_mount() -> None:
    tf = _round_trip(cv.static_tf(NODE, 0.0)).transforms
    assert {x.child_frame_id: (x.transform.translation.x, x.transform.translation.y, x.transform.translation.z)
            for x in tf} == SENSOR_MOUNTS
    assert {x.header.frame_id for x in tf} == {FRAME_BASE}
    assert all(x.transform.rotation.w == 1.0 for x in tf)
    from moose.signals import ImuSample

    assert cv.imu_to_msg(NODE, ImuSample(0.0, 0.0, 0.0, 0.0)).header.frame_id in SENSOR_MOUNTS


def _plan(state: np.ndarray, accel: np.ndarray) -> PlanResult:
    return PlanResult(accel, "converged", 3, 1e-3, 1.0, kinematic_rollout(state, accel, 0.2))


def test_markers_show_the_zone_its_width_and_the_three_paths() -> None:
    e = StateEstimate(2.0, 1.0, 0.2, 0.0, 7.0, 0.0, 0.0, 0.0)
    start = np.array([e.x, e.y, e.vX, e.vY])
    mpc = _plan(start, np.tile([0.0, 2.0], (10, 1)))
    msf = _plan(start, np.tile([0.0, 3.0], (10, 1)))
    zone = Obstacle(9.0, 11.0, -2.0, 2.0)
    threat = Threat(2.0, zone, 1.4, 2.0 - 0.2, 0.93, +1, 0.2)
    blend = Blend(0.25, 0.25 * mpc.accel + 0.75 * msf.accel)
    msg = _round_trip(cv.markers_to_msg(NODE, 2.0, threat, mpc, msf, blend_path(blend, e, 0.2)))
    by_ns = {m.ns: m for m in msg.markers}
    assert set(by_ns) == set(cv.MARKER_COLOURS)
    assert {m.header.frame_id for m in msg.markers} == {FRAME_ODOM} and {m.action for m in msg.markers} == {0}
    box = by_ns["danger_zone"]
    assert (box.pose.position.x, box.pose.position.y, box.scale.x, box.scale.y) == (10.0, 0.0, 2.0, 4.0)
    arrow = by_ns["danger_zone_width"].points
    assert (arrow[0].x, arrow[0].y, arrow[1].x, arrow[1].y) == pytest.approx((9.0, 0.2, 9.0, 2.0))  # y_path → far edge
    for ns, plan in (("mpc", mpc), ("msf", msf)):
        drawn = np.array([[p.x, p.y] for p in by_ns[ns].points])
        np.testing.assert_array_equal(drawn, plan.predicted[:, :2])
    drawn = np.array([[p.x, p.y] for p in by_ns["blend"].points])
    np.testing.assert_allclose(drawn, 0.25 * mpc.predicted[:, :2] + 0.75 * msf.predicted[:, :2], atol=1e-12)
    colours = {ns: (m.color.r, m.color.g, m.color.b) for ns, m in by_ns.items()}
    assert len(set(colours.values())) == len(colours)  # colour-coded


def test_markers_of_absent_things_are_deleted() -> None:
    e = StateEstimate(0.0, 0.0, 0.0, 0.0, 5.0, 0.0, 0.0, 0.0)
    msf = _plan(np.array([0.0, 0.0, 5.0, 0.0]), np.zeros((10, 2)))
    msg = _round_trip(cv.markers_to_msg(NODE, 0.0, None, None, msf, blend_path(Blend(0.0, msf.accel), e, 0.2)))
    actions = {m.ns: m.action for m in msg.markers}
    assert actions == {"danger_zone": 2, "danger_zone_width": 2, "mpc": 2, "msf": 0, "blend": 0}


def test_blend_path_of_the_msf_alone_is_the_msf_prediction() -> None:
    """Weight 0: the blended plan is the MSF's, so its path is the MSF planner's own prediction."""
    e = StateEstimate(1.0, 3.0, -0.5, 0.1, 6.0, 0.3, 0.0, 0.0)
    msf = _plan(np.array([e.x, e.y, e.vX, e.vY]), np.random.default_rng(1).uniform(-3, 3, (10, 2)))
    np.testing.assert_allclose(blend_path(Blend(0.0, msf.accel), e, 0.2), msf.predicted, atol=1e-12)


LAYOUT = __import__("pathlib").Path(__file__).resolve().parents[1] / "config" / "foxglove_layout.json"


def _field_type(type_name: str, fields: list[str]) -> str:
    """The type at ``fields`` inside ``type_name`` (``BASE:float64`` for a base field); KeyError if absent."""
    from rosbags.interfaces import Nodetype

    for i, name in enumerate(fields):
        node = dict(typestore().fielddefs[type_name][1])[name]
        if node[0] == Nodetype.NAME:
            type_name = node[1]
        elif node[0] == Nodetype.BASE and i == len(fields) - 1:
            return f"BASE:{node[1][0]}"
        else:
            raise KeyError(f"{name} of {type_name} is not a message or a scalar")
    return type_name


def test_foxglove_layout_names_only_what_the_graph_publishes() -> None:
    """Every panel of config/foxglove_layout.json is placed, and every topic, field and frame it names exists in
    the graph contract and the message definitions (a misspelt path would leave a plot empty)."""
    import json

    from moose_ros.graph import DIAGNOSTICS, FRAME_BASE, FRAME_ODOM, FRAME_TRUTH, MARKERS, TOPICS

    layout = json.loads(LAYOUT.read_text(encoding="utf-8"))
    config = layout["configById"]

    def placed(node):  # type: ignore[no-untyped-def]
        return {node} if isinstance(node, str) else placed(node["first"]) | placed(node["second"])

    assert placed(layout["layout"]) == set(config)
    kinds = {panel.split("!")[0] for panel in config}
    assert {"3D", "Plot", "DiagnosticSummary"} <= kinds
    three_d = config["3D!moose"]
    assert three_d["topics"][MARKERS.name]["visible"] and set(three_d["topics"]) <= set(TOPICS)
    assert {f"frame:{f}" for f in (FRAME_ODOM, FRAME_BASE, FRAME_TRUTH)} <= set(three_d["transforms"])
    assert config["DiagnosticSummary!moose"]["topicToRender"] == DIAGNOSTICS.name
    plotted = []
    for panel, cfg in config.items():
        if panel.startswith("Plot!"):
            for p in cfg["paths"]:
                topic, *fields = p["value"].split(".")
                assert _field_type(TOPICS[topic].type, fields).startswith("BASE:float"), p["value"]
                plotted.append(p["value"])
    for wanted in ("/vehicle/steering.delta", "/planning/blend.delta_mpc", "/control/reference.vx_ref",
                   "/planning/blend.weight_mpc", "/perception/threat.tau", "/perception/threat.nu"):
        assert wanted in plotted  # δ vs δ_MPC, v vs v_ref, w_MPC, τ/ν
