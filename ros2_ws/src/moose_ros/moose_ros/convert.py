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
from typing import Any, Callable, Optional

import numpy as np

from moose.signals import (
    ActuatorCommand, Blend, EpsSample, GpsSample, ImuSample, Obstacle, PlanResult, Reference, StateEstimate, Threat,
    WheelSpeedSample,
)

from .graph import (
    ACTUATOR_COMMAND, BLEND, DIAGNOSTICS, GPS, IMU, OBSTACLES, PLAN_MPC, PLAN_MSF, REFERENCE, STAMP_TOLERANCE, STATE,
    STEERING, THREAT, WHEEL_SPEEDS, Topic,
)

STATUS_CODES = {"converged": 0, "capped": 1, "failed": 2, "over_budget": 3, "ok": 4, "idle": 5}
STATUS_NAMES = {code: name for name, code in STATUS_CODES.items()}


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
        raise InvalidMessage(f"{kind}.{name_b} (length {b.size}) is invalid: expected the length of {name_a} ({a.size})")


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


def stamp(msg: Any, t: float, frame: str = "odom") -> None:
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


def plan_to_msg(node: Any, t: float, planner: str, plan: PlanResult) -> Any:
    msg = node.make("moose_msgs/msg/PlannerOutput")
    stamp(msg, t)
    msg.planner, msg.status, msg.iterations = planner, STATUS_CODES[plan.status], int(plan.iterations)
    msg.solve_time, msg.cost = float(plan.solve_time_s), float(plan.cost) if math.isfinite(plan.cost) else 1e300
    msg.accel_x, msg.accel_y = [float(v) for v in plan.accel[:, 0]], [float(v) for v in plan.accel[:, 1]]
    msg.predicted_x, msg.predicted_y = [float(v) for v in plan.predicted[:, 0]], [float(v) for v in plan.predicted[:, 1]]
    return msg


def plan_from_msg(msg: Any) -> PlanResult:
    """A planner's answer: a known status, finite accelerations of equal length (at least one step), a finite
    predicted path of equal length, a finite non-negative solve time, a finite cost (1e300 and above: none)."""
    if msg.status not in STATUS_NAMES:
        raise InvalidMessage(f"PlannerOutput.status = {msg.status!r} is invalid: expected one of {sorted(STATUS_NAMES)}")
    ax, ay = _finite_array("PlannerOutput", "accel_x", msg.accel_x), _finite_array("PlannerOutput", "accel_y", msg.accel_y)
    px = _finite_array("PlannerOutput", "predicted_x", msg.predicted_x)
    py = _finite_array("PlannerOutput", "predicted_y", msg.predicted_y)
    _same_length("PlannerOutput", ("accel_x", ax), ("accel_y", ay))
    _same_length("PlannerOutput", ("predicted_x", px), ("predicted_y", py), minimum=0)
    _finite("PlannerOutput", solve_time=msg.solve_time)
    if msg.solve_time < 0:
        raise InvalidMessage(f"PlannerOutput.solve_time = {msg.solve_time!r} is invalid: expected a time >= 0")
    if math.isnan(msg.cost):
        raise InvalidMessage(f"PlannerOutput.cost = {msg.cost!r} is invalid: expected a number (1e300: none)")
    predicted = np.zeros((px.size, 4))
    predicted[:, 0], predicted[:, 1] = px, py
    cost = msg.cost if msg.cost < 1e299 else math.inf
    return PlanResult(np.column_stack([ax, ay]), STATUS_NAMES[int(msg.status)], int(msg.iterations),  # type: ignore[arg-type]
                      msg.solve_time, cost, predicted)


def stamped_plan_from_msg(msg: Any, now: Optional[float] = None) -> tuple[float, PlanResult]:
    """(planning instant, plan) of a PlannerOutput."""
    return checked_time(msg, now), plan_from_msg(msg)


def blend_to_msg(node: Any, t: float, blend: Blend, reference: Reference) -> Any:
    msg = node.make("moose_msgs/msg/Blend")
    stamp(msg, t)
    msg.weight_mpc = float(blend.weight_mpc)
    msg.accel_x, msg.accel_y = [float(v) for v in blend.accel[:, 0]], [float(v) for v in blend.accel[:, 1]]
    msg.delta_ref, msg.vx_ref = reference.delta, reference.vx
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
    stamp(msg, s.t, "base_link")
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
    stamp(msg, s.t_measured)
    msg.child_frame_id = "gps"
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
    stamp(msg, s.t, "base_link")
    msg.omega_rl, msg.omega_rr = s.omega_rl, s.omega_rr
    return msg


def wheels_from_msg(msg: Any, now: Optional[float] = None) -> WheelSpeedSample:
    t = checked_time(msg, now)
    _finite("WheelSpeeds", omega_rl=msg.omega_rl, omega_rr=msg.omega_rr)
    return WheelSpeedSample(t, msg.omega_rl, msg.omega_rr)


def steering_to_msg(node: Any, s: EpsSample) -> Any:
    msg = node.make("moose_msgs/msg/SteeringReport")
    stamp(msg, s.t, "base_link")
    msg.delta = s.delta
    return msg


def steering_from_msg(msg: Any, now: Optional[float] = None) -> EpsSample:
    t = checked_time(msg, now)
    _finite("SteeringReport", delta=msg.delta)
    return EpsSample(t, msg.delta)


def odometry_to_msg(node: Any, t: float, state: np.ndarray) -> Any:
    """Ground-truth odometry (REP-105: pose in odom, twist in base_link)."""
    msg = node.make("nav_msgs/msg/Odometry")
    stamp(msg, t)
    msg.child_frame_id = "base_link"
    msg.pose.pose.position.x, msg.pose.pose.position.y = float(state[0]), float(state[1])
    msg.pose.pose.orientation.z, msg.pose.pose.orientation.w = math.sin(state[2] / 2), math.cos(state[2] / 2)
    msg.twist.twist.linear.x, msg.twist.twist.linear.y = float(state[3]), float(state[4])
    msg.twist.twist.angular.z = float(state[5])
    return msg


def actuator_to_msg(node: Any, t: float, reference: Reference, u: np.ndarray) -> Any:
    msg = node.make("moose_msgs/msg/ActuatorCommand")
    stamp(msg, t, "base_link")
    msg.steering_angle, msg.steering_rate = reference.delta, float(u[0])
    msg.torque_rl, msg.torque_rr = float(u[1]), float(u[2])
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
    BLEND.name: blend_from_msg,
    REFERENCE.name: reference_from_msg,
    ACTUATOR_COMMAND.name: actuator_from_msg,
    DIAGNOSTICS.name: statuses_from_msg,
}
"""The validating converter of every topic a node subscribes to: ``convert(msg, now)`` → the core's record
(plans: ``(instant, PlanResult)``; the threat: ``None`` when none is active; diagnostics: ``[(name, level,
message)]``), or :class:`InvalidMessage`.  ``now``: the receiver's clock, ``None`` while it is unknown."""


SENSOR_SAMPLES: dict[type, tuple[Topic, Callable[[Any, Any], Any]]] = {
    ImuSample: (IMU, imu_to_msg),
    GpsSample: (GPS, gps_to_msg),
    WheelSpeedSample: (WHEEL_SPEEDS, wheels_to_msg),
    EpsSample: (STEERING, steering_to_msg),
}
"""The topic and the converter of each vehicle sensor sample (simulator, CAN bridge, bags of lockstep runs)."""
