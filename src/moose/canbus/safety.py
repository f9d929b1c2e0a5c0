"""The bridge's command guard: nothing outside the vehicle limits reaches the car.

Whatever arrives on the command topic, the guard emits |δ| ≤ δ_max, |δ̇| ≤ the steering
rate limit (per command cycle), |δ̇_cmd| ≤ δ̇_max, |T| ≤ T_max and |Ṫ| ≤ the torque rate
limit.  A command with a non-finite field is invalid and ignored.  When the newest valid
command is older than ``timeout``, the guard emits the safe state: the steering held at the
last emitted angle with zero EPS rate, the torques ramped to zero at the torque rate limit
(from T_max in 0.1 s by default, so even the safe state respects every limit).  Fresh commands afterwards are followed again within
the rate limits, starting from the safe state.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Optional

from moose.params import VehicleParams, check, positive


@dataclasses.dataclass(frozen=True)
class GuardParams:
    delta_max: float = VehicleParams().delta_max
    """Steering angle limit (rad), Table I."""
    steer_rate_limit: float = 1.0
    """Steering angle rate limit at the bridge (rad/s): an EPS motor's capability; Table I's 2618 rad/s is not a sane bound."""
    eps_rate_max: float = 2.0
    """Limit of the EPS motor rate command (rad/s)."""
    torque_max: float = VehicleParams().T_max
    """Motor torque limit (N m), Table I."""
    torque_rate_limit: float = 2000.0
    """Torque rate limit (N m/s): 0 → T_max in 0.1 s."""
    timeout: float = 0.05
    """Age of the newest valid command after which the safe state is sent (s): five command cycles."""

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            check(f.name, getattr(self, f.name), positive, "a positive number")


@dataclasses.dataclass(frozen=True)
class Command:
    steering_angle: float
    steering_rate: float
    torque_rl: float
    torque_rr: float

    @property
    def valid(self) -> bool:
        return all(math.isfinite(v) for v in dataclasses.astuple(self))


SAFE = Command(0.0, 0.0, 0.0, 0.0)


class CommandGuard:
    """Limits, rate limits and the command timeout; ``output(t)`` is what may be sent at time t."""

    def __init__(self, params: GuardParams = GuardParams()) -> None:
        self.params = params
        self._latest: Optional[Command] = None
        self._received = -math.inf
        self._out = SAFE
        self._t_out: Optional[float] = None
        self.clamped = False
        self.timed_out = True
        self.invalid = 0

    def receive(self, command: Command, t: float) -> None:
        if not command.valid:
            self.invalid += 1
            return
        self._latest, self._received = command, t

    def output(self, t: float) -> Command:
        p = self.params
        dt = 0.0 if self._t_out is None else max(t - self._t_out, 0.0)
        self._t_out = t
        self.timed_out = self._latest is None or t - self._received > p.timeout
        if self.timed_out:
            step = p.torque_rate_limit * dt
            self._out = Command(self._out.steering_angle, 0.0, self._out.torque_rl - _clip(self._out.torque_rl, step),
                                self._out.torque_rr - _clip(self._out.torque_rr, step))
            return self._out
        want = self._latest
        assert want is not None
        angle = _clip(want.steering_angle, p.delta_max)
        angle = self._out.steering_angle + _clip(angle - self._out.steering_angle, p.steer_rate_limit * dt)
        torques = [o + _clip(_clip(w, p.torque_max) - o, p.torque_rate_limit * dt)
                   for w, o in ((want.torque_rl, self._out.torque_rl), (want.torque_rr, self._out.torque_rr))]
        rate = _clip(want.steering_rate, p.eps_rate_max)
        out = Command(angle, rate, torques[0], torques[1])
        self.clamped = out != want
        self._out = out
        return out


def _clip(value: float, bound: float) -> float:
    return min(max(value, -bound), bound)
