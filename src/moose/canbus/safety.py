"""The bridge's command guard: nothing outside the vehicle limits reaches the car.

Whatever arrives on the command topic, :meth:`CommandGuard.output` emits

* |δ_cmd| ≤ δ_max and |Δδ_cmd| ≤ δ̇_lim · Δt (the angle reference moves at most at the
  steering rate limit),
* |δ̇_cmd| ≤ δ̇_lim for the EPS motor rate command, and no rate towards an end stop the
  measured angle (EPS_STATUS) has reached: outwards at most (δ_max − |δ_meas|) / cycle,
* |T| ≤ T_max and |ΔT| ≤ Ṫ_lim · Δt for each rear motor

(δ_max and T_max from Table I, ``VehicleParams``).  A command with a non-finite field is
invalid: it discards the held command, so the guard is in the safe state until a valid
command arrives.  When the newest valid command is older than ``timeout`` the guard emits
the safe state too: the torques ramped to zero at Ṫ_lim (from T_max in 0.1 s by default)
and the steering either held (``safe_steering = "hold"``: the last emitted angle, EPS
rate 0) or returned to straight ahead at δ̇_lim (``"center"``).  The safe state itself
respects every limit, and a fresh command afterwards is followed from the safe state's
output, rate-limited.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Optional

from moose.params import ParamError, VehicleParams, check, positive

SAFE_STEERING = ("hold", "center")
_TIME_EPS = 1e-9
"""Round-off allowance on time differences (s): a command exactly ``timeout`` old is still valid."""


@dataclasses.dataclass(frozen=True)
class GuardParams:
    delta_max: float = VehicleParams().delta_max
    """Steering angle limit δ_max (rad), Table I."""
    steer_rate_limit: float = 2.0
    """Steering rate limit δ̇_lim at the bridge (rad/s), for the angle reference and the EPS rate command.

    Table I's 2618 rad/s (= 25 000 rpm, plausibly the EPS motor's speed rather than the road
    wheels') is not a usable bound.  2 rad/s is a fast EPS at the road wheels; the extreme case (7 m/s, τ = 1.4 s) still
    clears the obstacle by 0.15 m with it (0.04 m at 1 rad/s, 0.27 m unlimited; docs/design.md).
    """
    torque_max: float = VehicleParams().T_max
    """Motor torque limit T_max (N m), Table I."""
    torque_rate_limit: float = 2000.0
    """Torque rate limit Ṫ_lim (N m/s): 0 → T_max in 0.1 s."""
    timeout: float = 0.05
    """Age of the newest valid command after which the safe state is sent (s): five command cycles."""
    command_period: float = 0.01
    """Period of the command frames (s); the end-stop look-ahead."""
    safe_steering: str = "hold"
    """Steering in the safe state: ``hold`` the last angle, or ramp to ``center`` at the rate limit."""

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            if f.name != "safe_steering":
                check(f.name, getattr(self, f.name), positive, "a positive number")
        if self.safe_steering not in SAFE_STEERING:
            raise ParamError(f"safe_steering = {self.safe_steering!r} is invalid: expected one of {list(SAFE_STEERING)}")

    @property
    def eps_rate_max(self) -> float:
        """Limit of the EPS motor rate command (rad/s): the steering rate limit."""
        return self.steer_rate_limit

    @classmethod
    def from_vehicle(cls, vehicle: VehicleParams, **changes: object) -> "GuardParams":
        """δ_max and T_max of ``vehicle``; other fields from ``changes`` or the defaults."""
        return cls(delta_max=vehicle.delta_max, torque_max=vehicle.T_max, **changes)  # type: ignore[arg-type]


@dataclasses.dataclass(frozen=True)
class Command:
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
        try:
            return all(math.isfinite(float(v)) for v in dataclasses.astuple(self))
        except (TypeError, ValueError):
            return False


SAFE = Command(0.0, 0.0, 0.0, 0.0)


class CommandGuard:
    """Limits, rate limits, end stops and the command timeout; ``output(t)`` is what may be sent at time t."""

    def __init__(self, params: GuardParams = GuardParams()) -> None:
        self.params = params
        self._latest: Optional[Command] = None
        self._received = -math.inf
        self._out = SAFE
        self._t_out: Optional[float] = None
        self._measured: Optional[tuple[float, float]] = None
        self._invalid_latched = False
        self.clamped = False
        """A limit, rate limit or end stop changed the last output."""
        self.timed_out = True
        """The last output was the safe state (no valid command, or the newest one too old)."""
        self.invalid = 0
        """Invalid (non-finite) commands received."""

    def receive(self, command: Command, t: float) -> None:
        """A command from the motion controller, received at ``t``."""
        if not command.valid:
            self.invalid += 1
            self._invalid_latched = True
            self._latest = None
            return
        if t >= self._received:
            self._latest = Command(*(float(v) for v in dataclasses.astuple(command)))
            self._received = t

    def observe_angle(self, delta: float, t: float) -> None:
        """The steering angle the EPS measured (EPS_STATUS) at ``t``: end stops, and the initial angle to hold."""
        if not math.isfinite(delta) or not math.isfinite(t):
            return
        self._measured = (t, delta)
        if self._t_out is None:
            self._out = dataclasses.replace(self._out, steering_angle=_clip(delta, self.params.delta_max))

    def pop_invalid(self) -> bool:
        """An invalid command since the previous call (the status frame's flag)."""
        flag, self._invalid_latched = self._invalid_latched, False
        return flag

    def output(self, t: float) -> Command:
        p = self.params
        dt = 0.0 if self._t_out is None else max(t - self._t_out, 0.0)
        self._t_out = t
        old = self._out
        self.timed_out = self._latest is None or t - self._received > p.timeout + _TIME_EPS
        torque_step = p.torque_rate_limit * dt
        angle_step = p.steer_rate_limit * dt
        if self.timed_out:
            if p.safe_steering == "center":
                angle = old.steering_angle - _clip(old.steering_angle, angle_step)
                rate = (angle - old.steering_angle) / dt if dt > 0.0 else 0.0
            else:
                angle, rate = old.steering_angle, 0.0
            rate = self._end_stop(_clip(rate, p.steer_rate_limit), t)
            self._out = Command(angle, rate, old.torque_rl - _clip(old.torque_rl, torque_step),
                                old.torque_rr - _clip(old.torque_rr, torque_step))
            self.clamped = False
            return self._out
        want = self._latest
        assert want is not None
        angle = old.steering_angle + _clip(_clip(want.steering_angle, p.delta_max) - old.steering_angle, angle_step)
        torques = [o + _clip(_clip(w, p.torque_max) - o, torque_step)
                   for w, o in ((want.torque_rl, old.torque_rl), (want.torque_rr, old.torque_rr))]
        rate = self._end_stop(_clip(want.steering_rate, p.steer_rate_limit), t)
        out = Command(angle, rate, torques[0], torques[1])
        self.clamped = out != want
        self._out = out
        return out

    def _end_stop(self, rate: float, t: float) -> float:
        """No EPS rate that would carry the measured angle past ±δ_max within one command period."""
        if self._measured is None or t - self._measured[0] > self.params.timeout + _TIME_EPS:
            return rate
        delta, p = self._measured[1], self.params
        return min(max(rate, -max(p.delta_max + delta, 0.0) / p.command_period),
                   max(p.delta_max - delta, 0.0) / p.command_period)


def _clip(value: float, bound: float) -> float:
    return min(max(value, -bound), bound)
