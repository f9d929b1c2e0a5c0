"""Signals exchanged between the blocks of Fig. 3 (the data on its arrows).

Frames follow REP-103: the global frame ``odom`` has x along the initial
heading and y to the left; the body frame ``base_link`` has x forward and y
left.  Accelerations exchanged by the planners are global (v̇_X, v̇_Y) as in
eq. (skin); every quantity is in SI units.
"""
from __future__ import annotations

import dataclasses
import functools
import math
from typing import Any, Literal, Union

import numpy as np
from numpy.typing import ArrayLike

from .params import ParamError

PlanStatus = Literal["converged", "capped", "failed", "over_budget", "ok", "idle", "barrier_violated"]
"""Outcome of one planning step.

MPC: ``converged`` (tolerances met), ``capped`` (iteration/evaluation cap hit,
best iterate returned), ``failed`` (solver error or non-finite result),
``over_budget`` (wall time above the planning budget), ``barrier_violated``
(converged or capped, but the predicted path crosses the barrier y_safe of
eq. (ysafe) before the zone's far edge: the paper's "fails to provide a
solution").  MSF: ``ok``.  ``idle``: no obstacle, lane keeping only.
The codes on the wire are the ``STATUS_*`` constants of moose_msgs'
PlannerOutput, one per name.
"""


@dataclasses.dataclass(frozen=True)
class StateEstimate:
    """Output of the state observer (Fig. 3, perception)."""

    t: float
    x: float
    """Global CoG position x_ego (m)."""
    y: float
    """Global CoG position y_ego (m)."""
    theta: float
    """Yaw angle (rad)."""
    vx: float
    """Body longitudinal velocity (m/s)."""
    vy: float
    """Body lateral velocity (m/s)."""
    gamma: float
    """Yaw rate (rad/s)."""
    delta: float
    """Steering angle from the EPS (rad)."""

    @property
    def beta(self) -> float:
        """Sideslip angle β = atan(v_y / v_x) (rad), defined as 0 at standstill."""
        return float(np.arctan2(self.vy, self.vx)) if abs(self.vx) > 1e-6 else 0.0

    @property
    def vX(self) -> float:
        """Global velocity v_X = v_x cos θ − v_y sin θ (m/s)."""
        return float(self.vx * np.cos(self.theta) - self.vy * np.sin(self.theta))

    @property
    def vY(self) -> float:
        """Global velocity v_Y = v_x sin θ + v_y cos θ (m/s)."""
        return float(self.vx * np.sin(self.theta) + self.vy * np.cos(self.theta))


@dataclasses.dataclass(frozen=True)
class Obstacle:
    """An axis-aligned box in ``odom`` (m): an obstacle's danger zone, the box the CoG must avoid
    (also the drivable field of a scenario)."""

    x_min: float
    x_max: float
    y_min: float
    y_max: float

    def __post_init__(self) -> None:
        if not self.x_min < self.x_max:
            raise ParamError(f"x_min = {self.x_min!r} is invalid: expected below x_max = {self.x_max!r}")
        if not self.y_min < self.y_max:
            raise ParamError(f"y_min = {self.y_min!r} is invalid: expected below y_max = {self.y_max!r}")

    @functools.cached_property
    def _hash(self) -> int:
        return hash((self.x_min, self.x_max, self.y_min, self.y_max))

    def __hash__(self) -> int:
        """The hash of the fields, computed once (the detector looks a zone up several times per tick)."""
        return self._hash

    def contains(self, x: float, y: float) -> bool:
        """Whether the point (x, y) lies in the closed box."""
        return self.x_min <= x <= self.x_max and self.y_min <= y <= self.y_max

    def clearance(self, x: ArrayLike, y: ArrayLike) -> Any:
        """Signed distance of the point(s) (x, y) to the box (m): outside, the Euclidean distance to the box;
        inside, minus the distance to the nearest edge; zero on an edge.  A float (``numpy.float64``) for a
        point, an array for arrays; computed in double precision whatever the inputs' type."""
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        dx = np.maximum(self.x_min - x, x - self.x_max)
        dy = np.maximum(self.y_min - y, y - self.y_max)
        # the box's signed distance function: the distance outside plus the (negative) depth inside
        return np.hypot(np.maximum(dx, 0.0), np.maximum(dy, 0.0)) + np.minimum(np.maximum(dx, dy), 0.0)


@dataclasses.dataclass(frozen=True)
class Threat:
    """Output of the obstacle detector: the threat measures of Section III."""

    t: float
    obstacle: Obstacle
    tau: float
    """Time to collision τ: distance from the CoG to the near edge over v_x (s)."""
    w: float
    """Danger-zone width: lateral distance from the ego path to the obstacle's far edge on the evasion side (m)."""
    nu: float
    """Lateral steering index ν = w / y_max(τ, v_x), eq. (nudef)."""
    side: int
    """Evasion side: +1 to the left (positive y), -1 to the right."""
    y_path: float
    """Lateral position of the ego path the evasion starts from (m)."""


def time_to_collision(distance: float, vx: float) -> float:
    """τ = distance / v_x (s), eq. (nudef)'s τ (:attr:`Threat.tau`).

    Negative once the near edge is behind the CoG; infinite when the car is not
    closing in (v_x ≤ 0) on an obstacle ahead, 0 when it is not moving but already there.
    """
    if vx > 1e-9:
        return distance / vx
    return math.inf if distance > 0.0 else 0.0


@dataclasses.dataclass(frozen=True)
class PlannerInput:
    """What every planner receives at a planning instant (5 Hz)."""

    t: float
    estimate: StateEstimate
    threat: Threat | None
    v_des: float
    """Desired speed v_des (m/s)."""
    initial_guess: np.ndarray | None
    """(N_p, 2) global accelerations [v̇_X, v̇_Y]: the previous blend, shifted (or None)."""
    y_lane: float = 0.0
    """Lateral position of the lane the car returns to when no obstacle is reported (m)."""


@dataclasses.dataclass(frozen=True)
class PlanResult:
    """A planner's answer: an acceleration sequence over the horizon and how it was found."""

    accel: np.ndarray
    """(N_p, 2) global accelerations [v̇_X, v̇_Y] (m/s^2); row 0 is applied."""
    status: PlanStatus
    iterations: int
    solve_time_s: float
    cost: float
    predicted: np.ndarray
    """(N_p + 1, 4) predicted kinematic states [x, y, v_X, v_Y], row 0 the measured state."""


@dataclasses.dataclass(frozen=True)
class Blend:
    """Output of the weight function: the blended reference and the MPC's share."""

    weight_mpc: float
    """Weight of the MPC solution in [0, 1]; the MSF solution gets 1 − weight_mpc."""
    accel: np.ndarray
    """(N_p, 2) blended global accelerations; row 0 goes to the FBL, the rest seeds the next MPC solve."""


@dataclasses.dataclass(frozen=True)
class Reference:
    """Output of the FBL: the references of the motion controller."""

    delta: float
    """Reference steering angle δ* (rad)."""
    vx: float
    """Reference longitudinal speed v_x* (m/s)."""


@dataclasses.dataclass(frozen=True)
class ActuatorCommand:
    """Output of the motion controller to the vehicle's actuators (the EPS and the rear in-wheel motors)."""

    t: float
    steering_angle: float
    """Steering reference δ* for the EPS (rad)."""
    steering_rate: float
    """EPS motor rate command (rad/s)."""
    torque_rl: float
    """Rear-left motor torque (N m)."""
    torque_rr: float
    """Rear-right motor torque (N m)."""


@dataclasses.dataclass(frozen=True)
class ImuSample:
    """Body-frame IMU measurement (accelerometer specific force and gyro)."""

    t: float
    ax: float
    """Longitudinal acceleration a_x = v̇_x − v_y γ (m/s^2)."""
    ay: float
    """Lateral acceleration a_y = v̇_y + v_x γ (m/s^2)."""
    yaw_rate: float
    """γ (rad/s)."""


@dataclasses.dataclass(frozen=True)
class GpsSample:
    """GPS fix in the local ``odom`` frame, delivered ``lag`` seconds after ``t_measured``."""

    t: float
    """Delivery time (s)."""
    t_measured: float
    """Time the fix describes (s)."""
    x: float
    y: float
    vX: float
    vY: float


@dataclasses.dataclass(frozen=True)
class WheelSpeedSample:
    """Rear in-wheel motor speeds (rad/s)."""

    t: float
    omega_rl: float
    omega_rr: float


@dataclasses.dataclass(frozen=True)
class EpsSample:
    """Steering angle measured by the EPS (rad)."""

    t: float
    delta: float


Sample = Union[ImuSample, GpsSample, WheelSpeedSample, EpsSample]
"""A sensor sample of any of the car's sensors (what the sensor model emits and the observer fuses)."""
