"""Conversions between ROS messages and the core's records (the only place that knows both).

Messages are filled attribute by attribute, so the same code serves the rclpy classes
and the DDS dataclasses.

Received messages are validated here, and only here: every ``*_from_msg`` raises
:class:`InvalidMessage` (naming the field and the value) for a message the graph must not act on —
a number that is not finite, a geometry that is not a box (``x_min < x_max``, ``y_min < y_max``), an
enumeration out of range, arrays of unequal length, a stamp that is negative, malformed or more than
:data:`~moose_ros.graph.STAMP_TOLERANCE` ahead of the receiver's clock.  :data:`RECORDS` names the
converter of every topic a node subscribes to; nodes subscribe through
:meth:`moose_ros.nodes.base.GraphNode.subscribe`, which drops, counts and reports an invalid message
and never lets it raise out of a callback.
"""
from __future__ import annotations

import math
from functools import lru_cache
from typing import Any, Callable, Optional, Sequence, Union, cast, get_args

import numpy as np

from moose.signals import (
    ActuatorCommand,
    Blend,
    EpsSample,
    GpsSample,
    ImuSample,
    Obstacle,
    PlanResult,
    PlanStatus,
    Reference,
    StateEstimate,
    Threat,
    WheelSpeedSample,
)
from moose.state import GAMMA, STEER_RATE, THETA, TORQUE_RL, TORQUE_RR, VX, VY, X, Y

from .graph import (
    ACTUATOR_COMMAND,
    BLEND,
    DIAGNOSTICS,
    FRAME_BASE,
    FRAME_GPS,
    FRAME_IMU,
    FRAME_ODOM,
    FRAME_TRUTH,
    GPS,
    IMU,
    OBSTACLES,
    PLAN_MPC,
    PLAN_MSF,
    REFERENCE,
    SENSOR_MOUNTS,
    STAMP_TOLERANCE,
    STATE,
    STEERING,
    THREAT,
    WHEEL_SPEEDS,
    Topic,
)


@lru_cache(maxsize=1)
def status_codes() -> dict[PlanStatus, int]:
    """The wire code of each plan status: the ``STATUS_<NAME>`` constants of moose_msgs' ``PlannerOutput.msg``, the
    single definition (``STATUS_BARRIER_VIOLATED`` is ``barrier_violated``).  A status of the core without a
    constant, or a constant without a status, is an error here, not a message that cannot be sent."""
    from rosbags.typesys import get_types_from_msg

    from .interfaces import MSG_PACKAGE, msg_dir

    name = f"{MSG_PACKAGE}/msg/PlannerOutput"
    constants, _ = get_types_from_msg((msg_dir() / "PlannerOutput.msg").read_text(encoding="utf-8"), name)[name]
    codes = {const[len("STATUS_"):].lower(): int(value) for const, _kind, value in constants
             if const.startswith("STATUS_")}
    if set(codes) != set(get_args(PlanStatus)):
        raise RuntimeError(f"PlannerOutput.msg's STATUS_* constants {sorted(codes)} are not the plan statuses "
                           f"{sorted(get_args(PlanStatus))} of moose.signals.PlanStatus")
    return {cast(PlanStatus, status): code for status, code in codes.items()}


@lru_cache(maxsize=1)
def status_names() -> dict[int, PlanStatus]:
    """:func:`status_codes` inverted: the plan status of each wire code."""
    return {code: status for status, code in status_codes().items()}


class InvalidMessage(ValueError):
    """A received message the graph must not act on; ``str()`` names the message type, the field and the value."""


def _finite(kind: str, **fields: Any) -> None:
    """Raise :class:`InvalidMessage` unless every field is a finite number."""
    for name, value in fields.items():
        try:
            ok = math.isfinite(value)
        except TypeError:
            ok = False
        if not ok:
            raise InvalidMessage(f"{kind}.{name} = {value!r} is invalid: expected a finite number")


def _finite_array(kind: str, name: str, values: Any) -> np.ndarray:
    try:
        array = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise InvalidMessage(f"{kind}.{name} is invalid: expected numbers") from None
    bad = np.flatnonzero(~np.isfinite(array))
    if bad.size:
        raise InvalidMessage(f"{kind}.{name}[{bad[0]}] = {array[bad[0]]!r} is invalid: expected a finite number")
    return array


def _same_length(kind: str, first: tuple[str, np.ndarray], second: tuple[str, np.ndarray], minimum: int = 1) -> None:
    """Raise :class:`InvalidMessage` unless both arrays have one length of at least ``minimum``."""
    (name_a, a), (name_b, b) = first, second
    if a.size < minimum:
        raise InvalidMessage(f"{kind}.{name_a} (length {a.size}) is invalid: expected at least {minimum} element(s)")
    if a.shape != b.shape:
        raise InvalidMessage(f"{kind}.{name_b} (length {b.size}) is invalid: "
                             f"expected the length of {name_a} ({a.size})")


def checked_time(msg: Any, now: Optional[float] = None) -> float:
    """The header stamp of a received message (s), checked: ``0 <= nanosec < 1e9``, not negative, and — when the
    receiver's clock ``now`` is known — at most :data:`~moose_ros.graph.STAMP_TOLERANCE` ahead of it."""
    kind = type(msg).__name__
    sec, nanosec = msg.header.stamp.sec, msg.header.stamp.nanosec
    if not 0 <= nanosec < 1_000_000_000:
        raise InvalidMessage(f"{kind}.header.stamp.nanosec = {nanosec!r} is invalid: expected 0 .. 999999999")
    t = sec + 1e-9 * nanosec
    if sec < 0:
        raise InvalidMessage(f"{kind}.header.stamp = {t!r} s is invalid: expected a time >= 0")
    if now is not None and t > now + STAMP_TOLERANCE:
        raise InvalidMessage(f"{kind}.header.stamp = {t:.3f} s is invalid: {t - now:.3f} s ahead of this node's "
                             f"clock ({now:.3f} s; at most {STAMP_TOLERANCE:g} s allowed)")
    return t


def stamp(msg: Any, t: float, frame: str = FRAME_ODOM) -> None:
    """Set ``msg.header`` to time ``t`` (s) and ``frame``."""
    sec = math.floor(t)
    msg.header.stamp.sec = int(sec)
    msg.header.stamp.nanosec = min(int(round((t - sec) * 1e9)), 999_999_999)
    msg.header.frame_id = frame


def time_of(msg: Any) -> float:
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec


def estimate_to_msg(node: Any, e: StateEstimate) -> Any:
    msg = node.make("moose_msgs/msg/StateEstimate")
    stamp(msg, e.t)
    msg.x, msg.y, msg.theta, msg.vx, msg.vy, msg.gamma = e.x, e.y, e.theta, e.vx, e.vy, e.gamma
    msg.beta, msg.delta = e.beta, e.delta
    return msg


def estimate_from_msg(msg: Any, now: Optional[float] = None) -> StateEstimate:
    t = checked_time(msg, now)
    _finite("StateEstimate", x=msg.x, y=msg.y, theta=msg.theta, vx=msg.vx, vy=msg.vy, gamma=msg.gamma, beta=msg.beta,
            delta=msg.delta)
    return StateEstimate(t, msg.x, msg.y, msg.theta, msg.vx, msg.vy, msg.gamma, msg.delta)


def _fill_obstacle(msg: Any, o: Obstacle) -> None:
    msg.x_min, msg.x_max, msg.y_min, msg.y_max = o.x_min, o.x_max, o.y_min, o.y_max


def obstacle_from_msg(msg: Any, kind: str = "Obstacle") -> Obstacle:
    """A danger zone: finite corners of a box with ``x_min < x_max`` and ``y_min < y_max``."""
    _finite(kind, x_min=msg.x_min, x_max=msg.x_max, y_min=msg.y_min, y_max=msg.y_max)
    for low, high in (("x_min", "x_max"), ("y_min", "y_max")):
        if not getattr(msg, low) < getattr(msg, high):
            raise InvalidMessage(f"{kind}.{low} = {getattr(msg, low)!r} is invalid: expected below {kind}.{high} = "
                                 f"{getattr(msg, high)!r}")
    return Obstacle(msg.x_min, msg.x_max, msg.y_min, msg.y_max)


def obstacles_from_msg(msg: Any, now: Optional[float] = None) -> list[Obstacle]:
    """The danger zones of an ObstacleArray; one invalid zone makes the whole message invalid."""
    checked_time(msg, now)
    return [obstacle_from_msg(o, f"ObstacleArray.obstacles[{i}]") for i, o in enumerate(msg.obstacles)]


def obstacles_to_msg(node: Any, t: float, obstacles: list[Obstacle]) -> Any:
    msg = node.make("moose_msgs/msg/ObstacleArray")
    stamp(msg, t)
    items = []
    for o in obstacles:
        item = node.make("moose_msgs/msg/Obstacle")
        _fill_obstacle(item, o)
        items.append(item)
    msg.obstacles = items
    return msg


def threat_to_msg(node: Any, t: float, threat: Optional[Threat]) -> Any:
    msg = node.make("moose_msgs/msg/Threat")
    stamp(msg, t)
    msg.active = threat is not None
    if threat is not None:
        _fill_obstacle(msg.obstacle, threat.obstacle)
        msg.tau = threat.tau if math.isfinite(threat.tau) else 1e9
        msg.w, msg.side, msg.y_path = threat.w, int(threat.side), threat.y_path
        msg.nu = threat.nu if math.isfinite(threat.nu) else 1e9
    return msg


def threat_from_msg(msg: Any, now: Optional[float] = None) -> Optional[Threat]:
    """The threat, or None when none is active (τ and ν of 1e9 stand for "not closing in" / "no room", as sent)."""
    t = checked_time(msg, now)
    if not msg.active:
        return None
    obstacle = obstacle_from_msg(msg.obstacle, "Threat.obstacle")
    _finite("Threat", tau=msg.tau, w=msg.w, nu=msg.nu, y_path=msg.y_path)
    if msg.side not in (-1, 1):
        raise InvalidMessage(f"Threat.side = {msg.side!r} is invalid: expected -1 (right) or +1 (left)")
    return Threat(t, obstacle, msg.tau, msg.w, msg.nu, int(msg.side), msg.y_path)


def plan_to_msg(node: Any, t: float, planner: str, plan: PlanResult, with_threat: bool) -> Any:
    """A planner's answer at ``t``; ``with_threat``: it was planned against a reported threat."""
    msg = node.make("moose_msgs/msg/PlannerOutput")
    stamp(msg, t)
    msg.planner, msg.status, msg.iterations = planner, status_codes()[plan.status], int(plan.iterations)
    msg.with_threat = bool(with_threat)
    msg.solve_time, msg.cost = float(plan.solve_time_s), float(plan.cost) if math.isfinite(plan.cost) else 1e300
    msg.accel_x, msg.accel_y = [float(v) for v in plan.accel[:, 0]], [float(v) for v in plan.accel[:, 1]]
    msg.predicted_x, msg.predicted_y, msg.predicted_vx, msg.predicted_vy = (
        [float(v) for v in plan.predicted[:, i]] for i in range(4))
    return msg


def plan_from_msg(msg: Any) -> PlanResult:
    """A planner's answer: a known status, finite accelerations of equal length (at least one step), a finite
    predicted path (positions and velocities) of equal lengths, a finite non-negative solve time, a finite
    cost (1e300 and above: none)."""
    names = status_names()
    if msg.status not in names:
        raise InvalidMessage(f"PlannerOutput.status = {msg.status!r} is invalid: "
                             f"expected one of {sorted(names)}")
    ax = _finite_array("PlannerOutput", "accel_x", msg.accel_x)
    ay = _finite_array("PlannerOutput", "accel_y", msg.accel_y)
    _same_length("PlannerOutput", ("accel_x", ax), ("accel_y", ay))
    columns = [(f, _finite_array("PlannerOutput", f, getattr(msg, f)))
               for f in ("predicted_x", "predicted_y", "predicted_vx", "predicted_vy")]
    for column in columns[1:]:
        _same_length("PlannerOutput", columns[0], column, minimum=0)
    _finite("PlannerOutput", solve_time=msg.solve_time)
    if msg.solve_time < 0:
        raise InvalidMessage(f"PlannerOutput.solve_time = {msg.solve_time!r} is invalid: expected a time >= 0")
    if math.isnan(msg.cost):
        raise InvalidMessage(f"PlannerOutput.cost = {msg.cost!r} is invalid: expected a number (1e300: none)")
    predicted = np.column_stack([values for _, values in columns]) if columns[0][1].size else np.zeros((0, 4))
    cost = msg.cost if msg.cost < 1e299 else math.inf
    return PlanResult(np.column_stack([ax, ay]), names[int(msg.status)], int(msg.iterations),
                      msg.solve_time, cost, predicted)


def stamped_plan_from_msg(msg: Any, now: Optional[float] = None) -> tuple[float, bool, PlanResult]:
    """(planning instant, planned against a threat, plan) of a PlannerOutput."""
    return checked_time(msg, now), bool(msg.with_threat), plan_from_msg(msg)


def blend_to_msg(node: Any, t: float, blend: Blend, reference: Reference, delta_mpc: float = math.nan) -> Any:
    """The blend of a planning instant, its FBL reference and δ_MPC (``PlanningRecord.delta_mpc``)."""
    msg = node.make("moose_msgs/msg/Blend")
    stamp(msg, t)
    msg.weight_mpc = float(blend.weight_mpc)
    msg.accel_x, msg.accel_y = [float(v) for v in blend.accel[:, 0]], [float(v) for v in blend.accel[:, 1]]
    msg.delta_ref, msg.vx_ref, msg.delta_mpc = reference.delta, reference.vx, float(delta_mpc)
    return msg


def blend_from_msg(msg: Any, now: Optional[float] = None) -> Blend:
    """The blend: a weight in [0, 1] and finite accelerations of equal length (at least one step)."""
    checked_time(msg, now)
    _finite("Blend", weight_mpc=msg.weight_mpc, delta_ref=msg.delta_ref, vx_ref=msg.vx_ref)
    if not 0.0 <= msg.weight_mpc <= 1.0:
        raise InvalidMessage(f"Blend.weight_mpc = {msg.weight_mpc!r} is invalid: expected a weight in [0, 1]")
    ax, ay = _finite_array("Blend", "accel_x", msg.accel_x), _finite_array("Blend", "accel_y", msg.accel_y)
    _same_length("Blend", ("accel_x", ax), ("accel_y", ay))
    return Blend(float(msg.weight_mpc), np.column_stack([ax, ay]))


def stamped_blend_from_msg(msg: Any, now: Optional[float] = None) -> tuple[float, Blend]:
    """(planning instant, blend) of a Blend."""
    return checked_time(msg, now), blend_from_msg(msg)


def reference_to_msg(node: Any, t: float, reference: Reference) -> Any:
    msg = node.make("moose_msgs/msg/Reference")
    stamp(msg, t)
    msg.delta_ref, msg.vx_ref = reference.delta, reference.vx
    return msg


def reference_from_msg(msg: Any, now: Optional[float] = None) -> Reference:
    checked_time(msg, now)
    _finite("Reference", delta_ref=msg.delta_ref, vx_ref=msg.vx_ref)
    return Reference(delta=msg.delta_ref, vx=msg.vx_ref)


def imu_to_msg(node: Any, s: ImuSample) -> Any:
    msg = node.make("sensor_msgs/msg/Imu")
    stamp(msg, s.t, FRAME_IMU)
    msg.orientation_covariance = [-1.0] + [0.0] * 8  # no orientation estimate (REP-145)
    msg.angular_velocity.z = s.yaw_rate
    msg.linear_acceleration.x, msg.linear_acceleration.y = s.ax, s.ay
    return msg


def imu_from_msg(msg: Any, now: Optional[float] = None) -> ImuSample:
    t = checked_time(msg, now)
    a, w = msg.linear_acceleration, msg.angular_velocity
    _finite("Imu", **{"linear_acceleration.x": a.x, "linear_acceleration.y": a.y, "angular_velocity.z": w.z})
    return ImuSample(t, a.x, a.y, w.z)


def gps_to_msg(node: Any, s: GpsSample) -> Any:
    """A GPS fix as a local-frame Odometry stamped with its measurement time."""
    msg = node.make("nav_msgs/msg/Odometry")
    stamp(msg, s.t_measured, FRAME_ODOM)
    msg.child_frame_id = FRAME_GPS
    msg.pose.pose.position.x, msg.pose.pose.position.y = s.x, s.y
    msg.twist.twist.linear.x, msg.twist.twist.linear.y = s.vX, s.vY  # in odom axes
    return msg


def gps_from_msg(msg: Any, t_received: Optional[float] = None) -> GpsSample:
    """A GPS fix received at ``t_received`` (the receiver's clock; None: unknown, taken as the measurement time)."""
    t_measured = checked_time(msg, t_received)
    p, v = msg.pose.pose.position, msg.twist.twist.linear
    _finite("Odometry", **{"pose.pose.position.x": p.x, "pose.pose.position.y": p.y, "twist.twist.linear.x": v.x,
                           "twist.twist.linear.y": v.y})
    received = t_measured if t_received is None else max(t_received, t_measured)
    return GpsSample(received, t_measured, p.x, p.y, v.x, v.y)


def wheels_to_msg(node: Any, s: WheelSpeedSample) -> Any:
    msg = node.make("moose_msgs/msg/WheelSpeeds")
    stamp(msg, s.t, FRAME_BASE)
    msg.omega_rl, msg.omega_rr = s.omega_rl, s.omega_rr
    return msg


def wheels_from_msg(msg: Any, now: Optional[float] = None) -> WheelSpeedSample:
    t = checked_time(msg, now)
    _finite("WheelSpeeds", omega_rl=msg.omega_rl, omega_rr=msg.omega_rr)
    return WheelSpeedSample(t, msg.omega_rl, msg.omega_rr)


def steering_to_msg(node: Any, s: EpsSample) -> Any:
    msg = node.make("moose_msgs/msg/SteeringReport")
    stamp(msg, s.t, FRAME_BASE)
    msg.delta = s.delta
    return msg


def steering_from_msg(msg: Any, now: Optional[float] = None) -> EpsSample:
    t = checked_time(msg, now)
    _finite("SteeringReport", delta=msg.delta)
    return EpsSample(t, msg.delta)


def _yaw(quaternion: Any, theta: float) -> None:
    """A rotation by ``theta`` (rad) about z as a quaternion."""
    quaternion.x, quaternion.y = 0.0, 0.0
    quaternion.z, quaternion.w = math.sin(theta / 2), math.cos(theta / 2)


def odometry_to_msg(node: Any, t: float, state: np.ndarray) -> Any:
    """Ground-truth odometry (REP-105: pose in odom, twist in the true body frame ``base_link_truth``)."""
    msg = node.make("nav_msgs/msg/Odometry")
    stamp(msg, t, FRAME_ODOM)
    msg.child_frame_id = FRAME_TRUTH
    msg.pose.pose.position.x, msg.pose.pose.position.y = float(state[X]), float(state[Y])
    _yaw(msg.pose.pose.orientation, float(state[THETA]))
    msg.twist.twist.linear.x, msg.twist.twist.linear.y = float(state[VX]), float(state[VY])
    msg.twist.twist.angular.z = float(state[GAMMA])
    return msg


def actuator_to_msg(node: Any, t: float, reference: Reference, u: Union[np.ndarray, Sequence[float]]) -> Any:
    msg = node.make("moose_msgs/msg/ActuatorCommand")
    stamp(msg, t, FRAME_BASE)
    msg.steering_angle, msg.steering_rate = reference.delta, float(u[STEER_RATE])
    msg.torque_rl, msg.torque_rr = float(u[TORQUE_RL]), float(u[TORQUE_RR])
    return msg


def actuator_from_msg(msg: Any, now: Optional[float] = None) -> ActuatorCommand:
    t = checked_time(msg, now)
    _finite("ActuatorCommand", steering_angle=msg.steering_angle, steering_rate=msg.steering_rate,
            torque_rl=msg.torque_rl, torque_rr=msg.torque_rr)
    return ActuatorCommand(t, msg.steering_angle, msg.steering_rate, msg.torque_rl, msg.torque_rr)


def diagnostic_to_msg(node: Any, t: float, name: str, level: int, message: str, values: dict[str, Any]) -> Any:
    status = node.make("diagnostic_msgs/msg/DiagnosticStatus")
    status.level = bytes([level]) if isinstance(status.level, bytes) else level  # rclpy maps byte to bytes
    status.name, status.message, status.hardware_id = name, message, "moose"
    pairs = []
    for key, value in values.items():
        pair = node.make("diagnostic_msgs/msg/KeyValue")
        pair.key, pair.value = key, str(value)
        pairs.append(pair)
    status.values = pairs
    msg = node.make("diagnostic_msgs/msg/DiagnosticArray")
    stamp(msg, t, "")
    msg.status = [status]
    return msg


def _transform(node: Any, t: float, parent: str, child: str, x: float, y: float, z: float = 0.0,
               theta: float = 0.0) -> Any:
    msg = node.make("geometry_msgs/msg/TransformStamped")
    stamp(msg, t, parent)
    msg.child_frame_id = child
    msg.transform.translation.x, msg.transform.translation.y, msg.transform.translation.z = x, y, z
    _yaw(msg.transform.rotation, theta)
    return msg


def estimate_tf(node: Any, e: StateEstimate) -> Any:
    """``/tf``: odom → base_link, the observer's estimate (REP-105: the state estimator's transform)."""
    msg = node.make("tf2_msgs/msg/TFMessage")
    msg.transforms = [_transform(node, e.t, FRAME_ODOM, FRAME_BASE, e.x, e.y, theta=e.theta)]
    return msg


def truth_tf(node: Any, t: float, state: np.ndarray) -> Any:
    """``/tf``: odom → base_link_truth, the simulator's ground truth (plant state [x, y, θ, …])."""
    msg = node.make("tf2_msgs/msg/TFMessage")
    msg.transforms = [_transform(node, t, FRAME_ODOM, FRAME_TRUTH, float(state[X]), float(state[Y]),
                                 theta=float(state[THETA]))]
    return msg


def static_tf(node: Any, t: float) -> Any:
    """``/tf_static``: base_link → each sensor frame at its mount (:data:`moose_ros.graph.SENSOR_MOUNTS`)."""
    msg = node.make("tf2_msgs/msg/TFMessage")
    msg.transforms = [_transform(node, t, FRAME_BASE, frame, *mount) for frame, mount in SENSOR_MOUNTS.items()]
    return msg


MARKER_COLOURS: dict[str, tuple[float, float, float, float]] = {
    "danger_zone": (0.84, 0.15, 0.16, 0.6),   # the paper's red box
    "danger_zone_width": (1.0, 0.5, 0.05, 1.0),
    "mpc": (0.12, 0.47, 0.71, 1.0),           # blue
    "msf": (0.17, 0.63, 0.17, 1.0),           # green
    "blend": (0.0, 0.0, 0.0, 1.0),            # black: what the car is asked to follow
}
"""RGBA of each marker namespace of ``/planning/markers`` (the Foxglove layout's legend)."""
MARKER_LINE_WIDTH = 0.08
"""Width of the predicted paths (m)."""
ZONE_HEIGHT = 1.0
"""Drawn height of the danger zone (m): a box on the ground; the zone itself is 2-D."""
_ARROW, _CUBE, _LINE_STRIP = 0, 1, 4
_ADD, _DELETE = 0, 2


def _marker(node: Any, t: float, ns: str, kind: int) -> Any:
    m = node.make("visualization_msgs/msg/Marker")
    stamp(m, t, FRAME_ODOM)
    m.ns, m.id, m.type, m.action = ns, 0, kind, _ADD
    m.pose.orientation.w = 1.0
    m.color.r, m.color.g, m.color.b, m.color.a = MARKER_COLOURS[ns]
    return m


def _point(node: Any, x: float, y: float, z: float = 0.0) -> Any:
    p = node.make("geometry_msgs/msg/Point")
    p.x, p.y, p.z = float(x), float(y), float(z)
    return p


def _path(node: Any, t: float, ns: str, path: Optional[np.ndarray]) -> Any:
    m = _marker(node, t, ns, _LINE_STRIP)
    if path is None or len(path) < 2:
        m.action = _DELETE
        return m
    m.scale.x = MARKER_LINE_WIDTH
    m.points = [_point(node, x, y) for x, y in np.asarray(path, dtype=float)[:, :2]]
    return m


def markers_to_msg(node: Any, t: float, threat: Optional[Threat], mpc: Optional[PlanResult],
                   msf: Optional[PlanResult], blend: Optional[np.ndarray]) -> Any:
    """``/planning/markers`` of one planning instant, in odom: the danger zone (the box the CoG must avoid,
    the paper's red box) and its width w from the ego path toward the evasion side (a Threat's ``y_path``,
    ``side`` and ``w``), and the predicted paths of the MPC and the MSF planner (``PlanResult.predicted``)
    and of the blend (``blend``: (N + 1, ≥ 2) positions, :func:`moose.planner.step.blend_path`).  What is
    absent is deleted (action DELETE), so a viewer never keeps a stale zone or path."""
    zone = _marker(node, t, "danger_zone", _CUBE)
    width = _marker(node, t, "danger_zone_width", _ARROW)
    if threat is None:
        zone.action = width.action = _DELETE
    else:
        o = threat.obstacle
        zone.pose.position.x, zone.pose.position.y = 0.5 * (o.x_min + o.x_max), 0.5 * (o.y_min + o.y_max)
        zone.pose.position.z = 0.5 * ZONE_HEIGHT
        zone.scale.x, zone.scale.y, zone.scale.z = o.x_max - o.x_min, o.y_max - o.y_min, ZONE_HEIGHT
        width.points = [_point(node, o.x_min, threat.y_path, 0.05),
                        _point(node, o.x_min, threat.y_path + threat.side * threat.w, 0.05)]
        width.scale.x, width.scale.y, width.scale.z = 0.1, 0.3, 0.4  # shaft and head diameter, head length
    msg = node.make("visualization_msgs/msg/MarkerArray")
    msg.markers = [zone, width, _path(node, t, "mpc", mpc.predicted if mpc is not None else None),
                   _path(node, t, "msf", msf.predicted if msf is not None else None), _path(node, t, "blend", blend)]
    return msg


def statuses_from_msg(msg: Any, now: Optional[float] = None) -> list[tuple[str, int, str]]:
    """(name, level, message) of each status of a DiagnosticArray: a non-empty name, a level OK..STALE (0..3)."""
    checked_time(msg, now)
    out = []
    for i, status in enumerate(msg.status):
        level = status.level[0] if isinstance(status.level, (bytes, bytearray)) else status.level
        if level not in (0, 1, 2, 3) or not status.name:
            raise InvalidMessage(f"DiagnosticArray.status[{i}] (name {status.name!r}, level {level!r}) is invalid: "
                                 "expected a name and a level 0..3")
        out.append((status.name, int(level), status.message))
    return out


RECORDS: dict[str, Callable[[Any, Optional[float]], Any]] = {
    IMU.name: imu_from_msg,
    GPS.name: gps_from_msg,
    WHEEL_SPEEDS.name: wheels_from_msg,
    STEERING.name: steering_from_msg,
    OBSTACLES.name: obstacles_from_msg,
    STATE.name: estimate_from_msg,
    THREAT.name: threat_from_msg,
    PLAN_MPC.name: stamped_plan_from_msg,
    PLAN_MSF.name: stamped_plan_from_msg,
    BLEND.name: stamped_blend_from_msg,
    REFERENCE.name: reference_from_msg,
    ACTUATOR_COMMAND.name: actuator_from_msg,
    DIAGNOSTICS.name: statuses_from_msg,
}
"""The validating converter of every topic a node subscribes to: ``convert(msg, now)`` → the core's record
(plans: ``(instant, with threat, PlanResult)``; blends: ``(instant, Blend)``; the threat: ``None`` when none is
active; diagnostics: ``[(name, level, message)]``), or :class:`InvalidMessage`.  ``now``: the receiver's clock,
``None`` while it is unknown."""


SENSOR_SAMPLES: dict[type, tuple[Topic, Callable[[Any, Any], Any]]] = {
    ImuSample: (IMU, imu_to_msg),
    GpsSample: (GPS, gps_to_msg),
    WheelSpeedSample: (WHEEL_SPEEDS, wheels_to_msg),
    EpsSample: (STEERING, steering_to_msg),
}
"""The topic and the converter of each vehicle sensor sample (simulator, CAN bridge, bags of lockstep runs)."""
