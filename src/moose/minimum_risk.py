"""The minimum-risk maneuver: what the car does when the stack can no longer drive it.

One law, used wherever the stack gives up control:

* the CAN bridge's command guard (:mod:`moose.canbus.safety`) when commands stop (a dead, stalled or
  invalid motion controller);
* the motion controller node when what it needs is stale or failed (the estimate, the reference, the
  steering angle, or an upstream node that reports an error or fell silent);
* the simulator's topic-side vehicle I/O, which plays the bridge's role in the topic graph (through the
  same guard).

Per command period T (one call of :meth:`MinimumRiskManeuver.step`), from the previous output:

* **steer back to straight ahead**: the angle reference ramps to 0 at δ̇_max; the EPS rate command is
  −K_δ · δ_meas (the measured angle, when fresh; 0 within ``straight_tolerance``, so the EPS does not
  chase the sensor's noise) or the reference's ramp (no fresh measurement), clipped to δ̇_max.  Never
  the last steering angle held: a car that holds its angle drives in a circle.
* **brake with the rear motors** (regeneration; the car has no other brake on the bus):
  T_rl = T_rr = −clip(k_ω · ω̄, ±T_brake), ω̄ the mean measured rear wheel speed.  Equal torques add no
  yaw moment; a torque that falls with the wheel speed lets a locking wheel recover instead of staying
  locked, and near standstill the car slows exponentially (time constant m r² / 2k_ω) instead of
  reversing.  Without fresh wheel speeds the target torque is zero (the car coasts: braking blind could
  drive it backwards).
* **stopped** once ω̄ has stayed within ``stop_speed`` for ``stop_time``: zero torque from then on.

Every output then goes through the vehicle's limits (:meth:`ActuatorLimits.limit`): |δ| ≤ δ_max,
|Δδ| ≤ δ̇_max T, |δ̇_cmd| ≤ δ̇_max and no rate towards an end stop the measured angle has reached,
|T| ≤ T_max and |ΔT| ≤ Ṫ_max T.  The car stops along its heading, not back in its lane (nothing at
this level knows a lane): docs/graph.md, "Minimum-risk maneuver", has the measured distances.
"""
from __future__ import annotations

import dataclasses
import math
import numbers
from typing import Optional

from .schema import MinimumRiskParams

_TIME_EPS = 1e-9


@dataclasses.dataclass(frozen=True)
class Command:
    """An actuator command: what a command frame carries (config/kanon.dbc CMD_STEER, CMD_TORQUE)."""

    steering_angle: float
    """δ* (rad)."""
    steering_rate: float
    """EPS motor rate command δ̇_cmd (rad/s)."""
    torque_rl: float
    """Rear-left motor torque (N m)."""
    torque_rr: float
    """Rear-right motor torque (N m)."""

    @property
    def valid(self) -> bool:
        """Every field a finite real number (not a bool, a string, or an integer too large for a float)."""
        try:
            return all(isinstance(v, numbers.Real) and not isinstance(v, bool) and math.isfinite(v)
                       for v in dataclasses.astuple(self))
        except (OverflowError, TypeError, ValueError):
            return False


@dataclasses.dataclass(frozen=True)
class ActuatorLimits:
    """The actuators' limits an output must respect (the vehicle's, or tighter)."""

    delta_max: float
    """Steering angle δ_max (rad)."""
    steer_rate_limit: float
    """Steering rate δ̇_max (rad/s) of the angle reference and of the EPS rate command."""
    torque_max: float
    """Torque T_max of one rear motor (N m)."""
    torque_rate_limit: float
    """Torque rate Ṫ_max of one rear motor (N m/s)."""

    @classmethod
    def from_vehicle(cls, vehicle: object) -> "ActuatorLimits":
        """The limits of ``vehicle`` (a :class:`~moose.params.VehicleParams`)."""
        return cls(vehicle.delta_max, vehicle.delta_rate_max, vehicle.T_max,  # type: ignore[attr-defined]
                   vehicle.torque_rate_max)  # type: ignore[attr-defined]

    def limit(self, want: Command, old: Command, period: float, measured_angle: Optional[float] = None) -> Command:
        """``want`` clipped to the limits, rate-limited from ``old`` over one ``period``, end stops applied
        (no EPS rate that would carry ``measured_angle`` past ±δ_max within the period)."""
        angle = old.steering_angle + _clip(_clip(want.steering_angle, self.delta_max) - old.steering_angle,
                                           self.steer_rate_limit * period)
        torques = [o + _clip(_clip(w, self.torque_max) - o, self.torque_rate_limit * period)
                   for w, o in ((want.torque_rl, old.torque_rl), (want.torque_rr, old.torque_rr))]
        rate = _clip(want.steering_rate, self.steer_rate_limit)
        if measured_angle is not None:
            rate = min(max(rate, -max(self.delta_max + measured_angle, 0.0) / period),
                       max(self.delta_max - measured_angle, 0.0) / period)
        return Command(angle, rate, torques[0], torques[1])


class MinimumRiskManeuver:
    """The law of the module docstring, one output per ``period`` (s)."""

    def __init__(self, params: MinimumRiskParams, limits: ActuatorLimits, period: float) -> None:
        self.params = params
        self.limits = limits
        self.period = float(period)
        self.stopped = False
        """The car has stood still for ``stop_time``: the braking torque is released."""
        self._still = 0

    @property
    def brake_torque(self) -> float:
        """T_brake (N m per rear motor)."""
        return self.params.brake_fraction * self.limits.torque_max

    def reset(self) -> None:
        """Forget the standstill count (a new maneuver)."""
        self.stopped = False
        self._still = 0

    def target(self, old: Command, measured_angle: Optional[float], wheel_speed: Optional[float]) -> Command:
        """What the maneuver asks for after ``old``, before the limits.  ``measured_angle`` (rad) and
        ``wheel_speed`` (ω̄, rad/s) are ``None`` when not fresh."""
        p = self.params
        angle = old.steering_angle - _clip(old.steering_angle, self.limits.steer_rate_limit * self.period)
        if measured_angle is None:
            rate = (angle - old.steering_angle) / self.period
        else:
            rate = 0.0 if abs(measured_angle) <= p.straight_tolerance else -p.eps_gain * measured_angle
        torque = 0.0
        if wheel_speed is None:
            self._still = 0
        elif not self.stopped:
            self._still = self._still + 1 if abs(wheel_speed) <= p.stop_speed else 0
            if self._still * self.period >= p.stop_time - _TIME_EPS:
                self.stopped = True
            else:
                torque = -_clip(p.brake_gain * wheel_speed, self.brake_torque)
        return Command(angle, rate, torque, torque)

    def step(self, old: Command, measured_angle: Optional[float], wheel_speed: Optional[float]) -> Command:
        """The next output after ``old``: :meth:`target` within the limits."""
        return self.limits.limit(self.target(old, measured_angle, wheel_speed), old, self.period, measured_angle)


def _clip(value: float, bound: float) -> float:
    return min(max(value, -bound), bound)
