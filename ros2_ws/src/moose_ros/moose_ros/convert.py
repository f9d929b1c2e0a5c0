"""Conversions between ROS messages and the core's records (the only place that knows both).

Messages are filled attribute by attribute, so the same code serves the rclpy classes
and the DDS dataclasses.
"""
from __future__ import annotations

import math
from typing import Any, Callable, Optional

import numpy as np

from moose.signals import (
    Blend, EpsSample, GpsSample, ImuSample, Obstacle, PlanResult, Reference, StateEstimate, Threat, WheelSpeedSample,
)

from .graph import GPS, IMU, STEERING, WHEEL_SPEEDS, Topic

STATUS_CODES = {"converged": 0, "capped": 1, "failed": 2, "over_budget": 3, "ok": 4, "idle": 5}
STATUS_NAMES = {code: name for name, code in STATUS_CODES.items()}


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


def estimate_from_msg(msg: Any) -> StateEstimate:
    return StateEstimate(time_of(msg), msg.x, msg.y, msg.theta, msg.vx, msg.vy, msg.gamma, msg.delta)


def _fill_obstacle(msg: Any, o: Obstacle) -> None:
    msg.x_min, msg.x_max, msg.y_min, msg.y_max = o.x_min, o.x_max, o.y_min, o.y_max


def obstacle_from_msg(msg: Any) -> Obstacle:
    return Obstacle(msg.x_min, msg.x_max, msg.y_min, msg.y_max)


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


def threat_from_msg(msg: Any) -> Optional[Threat]:
    if not msg.active:
        return None
    return Threat(time_of(msg), obstacle_from_msg(msg.obstacle), msg.tau, msg.w, msg.nu, int(msg.side), msg.y_path)


def plan_to_msg(node: Any, t: float, planner: str, plan: PlanResult) -> Any:
    msg = node.make("moose_msgs/msg/PlannerOutput")
    stamp(msg, t)
    msg.planner, msg.status, msg.iterations = planner, STATUS_CODES[plan.status], int(plan.iterations)
    msg.solve_time, msg.cost = float(plan.solve_time_s), float(plan.cost) if math.isfinite(plan.cost) else 1e300
    msg.accel_x, msg.accel_y = [float(v) for v in plan.accel[:, 0]], [float(v) for v in plan.accel[:, 1]]
    msg.predicted_x, msg.predicted_y = [float(v) for v in plan.predicted[:, 0]], [float(v) for v in plan.predicted[:, 1]]
    return msg


def plan_from_msg(msg: Any) -> PlanResult:
    accel = np.column_stack([np.asarray(msg.accel_x, float), np.asarray(msg.accel_y, float)])
    predicted = np.zeros((len(msg.predicted_x), 4))
    predicted[:, 0], predicted[:, 1] = msg.predicted_x, msg.predicted_y
    cost = msg.cost if msg.cost < 1e299 else math.inf
    return PlanResult(accel, STATUS_NAMES[int(msg.status)], int(msg.iterations), msg.solve_time, cost, predicted)  # type: ignore[arg-type]


def blend_to_msg(node: Any, t: float, blend: Blend, reference: Reference) -> Any:
    msg = node.make("moose_msgs/msg/Blend")
    stamp(msg, t)
    msg.weight_mpc = float(blend.weight_mpc)
    msg.accel_x, msg.accel_y = [float(v) for v in blend.accel[:, 0]], [float(v) for v in blend.accel[:, 1]]
    msg.delta_ref, msg.vx_ref = reference.delta, reference.vx
    return msg


def blend_accel(msg: Any) -> np.ndarray:
    return np.column_stack([np.asarray(msg.accel_x, float), np.asarray(msg.accel_y, float)])


def reference_to_msg(node: Any, t: float, reference: Reference) -> Any:
    msg = node.make("moose_msgs/msg/Reference")
    stamp(msg, t)
    msg.delta_ref, msg.vx_ref = reference.delta, reference.vx
    return msg


def reference_from_msg(msg: Any) -> Reference:
    return Reference(delta=msg.delta_ref, vx=msg.vx_ref)


def imu_to_msg(node: Any, s: ImuSample) -> Any:
    msg = node.make("sensor_msgs/msg/Imu")
    stamp(msg, s.t, "base_link")
    msg.orientation_covariance = [-1.0] + [0.0] * 8  # no orientation estimate (REP-145)
    msg.angular_velocity.z = s.yaw_rate
    msg.linear_acceleration.x, msg.linear_acceleration.y = s.ax, s.ay
    return msg


def imu_from_msg(msg: Any) -> ImuSample:
    return ImuSample(time_of(msg), msg.linear_acceleration.x, msg.linear_acceleration.y, msg.angular_velocity.z)


def gps_to_msg(node: Any, s: GpsSample) -> Any:
    """A GPS fix as a local-frame Odometry stamped with its measurement time."""
    msg = node.make("nav_msgs/msg/Odometry")
    stamp(msg, s.t_measured)
    msg.child_frame_id = "gps"
    msg.pose.pose.position.x, msg.pose.pose.position.y = s.x, s.y
    msg.twist.twist.linear.x, msg.twist.twist.linear.y = s.vX, s.vY  # in odom axes
    return msg


def gps_from_msg(msg: Any, t_received: float) -> GpsSample:
    t_measured = time_of(msg)
    return GpsSample(max(t_received, t_measured), t_measured, msg.pose.pose.position.x, msg.pose.pose.position.y,
                     msg.twist.twist.linear.x, msg.twist.twist.linear.y)


def wheels_to_msg(node: Any, s: WheelSpeedSample) -> Any:
    msg = node.make("moose_msgs/msg/WheelSpeeds")
    stamp(msg, s.t, "base_link")
    msg.omega_rl, msg.omega_rr = s.omega_rl, s.omega_rr
    return msg


def wheels_from_msg(msg: Any) -> WheelSpeedSample:
    return WheelSpeedSample(time_of(msg), msg.omega_rl, msg.omega_rr)


def steering_to_msg(node: Any, s: EpsSample) -> Any:
    msg = node.make("moose_msgs/msg/SteeringReport")
    stamp(msg, s.t, "base_link")
    msg.delta = s.delta
    return msg


def steering_from_msg(msg: Any) -> EpsSample:
    return EpsSample(time_of(msg), msg.delta)


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


SENSOR_SAMPLES: dict[type, tuple[Topic, Callable[[Any, Any], Any]]] = {
    ImuSample: (IMU, imu_to_msg),
    GpsSample: (GPS, gps_to_msg),
    WheelSpeedSample: (WHEEL_SPEEDS, wheels_to_msg),
    EpsSample: (STEERING, steering_to_msg),
}
"""The topic and the converter of each vehicle sensor sample (simulator, CAN bridge, bags of lockstep runs)."""
