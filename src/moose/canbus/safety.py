"""The bridge's command guard: nothing outside the vehicle's limits reaches the car, and a silent
controller ends in a stop.

**Limits.**  Whatever arrives on the command topic, every output of
:meth:`CommandGuard.output` (one per command frame, period T_cmd) satisfies

* |δ_cmd| ≤ δ_max and |Δδ_cmd| ≤ δ̇_max · T_cmd (the angle reference moves at most at the
  steering rate),
* |δ̇_cmd| ≤ δ̇_max for the EPS motor rate command, and no rate towards an end stop the
  measured angle (EPS_STATUS) has reached: outwards at most (δ_max − |δ_meas|) / T_cmd,
* |T| ≤ T_max and |ΔT| ≤ Ṫ_max · T_cmd for each rear motor.

The four limits are the vehicle's (:class:`moose.params.VehicleParams`, bounded by
:data:`moose.params.VEHICLE_LIMITS`): :class:`GuardParams` refuses a looser value, so
configuration can only tighten them.  The rate limits are per output, not per second of
the caller's clock, so no clock step can widen them.

**Time.**  The guard ages its inputs in two ways and takes the older: command cycles
(outputs since the input arrived, times T_cmd) and the caller's clock between outputs,
counting forward steps only.  A clock that stops or steps back therefore delays a
timeout by at most one cycle; a forward step or a stalled caller ages the inputs at once.
An input that arrived since the previous output is always fresh.  The caller passes a
monotonic time (the bridge runner: ``time.monotonic()``; lockstep simulation: simulated
time).

**States** (:class:`GuardState`).  ``idle`` until the first valid command: zero torque,
EPS rate 0, the angle reference at the measured angle.  ``commanding`` while the newest
valid command is at most ``timeout`` old: the command, limited.  A command with a
non-finite field is invalid and discards the held command.  When the newest valid command
is older than ``timeout`` (or was discarded) the guard runs the **minimum-risk maneuver**
(:mod:`moose.minimum_risk`: steer back to straight ahead, brake with the rear motors; the law the
motion controller and the simulator's topic I/O run too), its targets limited like any command,
from the EPS angle and rear wheel speeds the guard last observed (only fresh ones count).  Once
the maneuver reports the car stopped, the state is ``stopped``: zero torque, steering centred.  A
fresh valid command returns to ``commanding``, followed from the last output at the rate limits.
"""
from __future__ import annotations

import dataclasses
import enum
import math
import numbers
from typing import Any, Optional

from moose.minimum_risk import ActuatorLimits, Command, MinimumRiskManeuver
from moose.params import VEHICLE_LIMITS, ParamError, VehicleParams, at_most, check
from moose.schema import MinimumRiskParams

from .ecu import ECU_TIMEOUT

_TIME_EPS = 1e-9
"""Round-off allowance on ages (s): an input exactly ``timeout`` old is still fresh."""

HARD_LIMIT = {"delta_max": "delta_max", "steer_rate_limit": "delta_rate_max", "torque_max": "T_max",
              "torque_rate_limit": "torque_rate_max"}
"""Each limit of the guard and the field of :class:`moose.params.VehicleLimits` that bounds it."""


def _positive_finite(value: object) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool) and 0.0 < float(value) < math.inf


@dataclasses.dataclass(frozen=True)
class GuardParams:
    """Limits, timeout and minimum-risk maneuver of the guard (SI units).

    Build it with :meth:`from_vehicle` so the limits are the configured vehicle's.
    """

    delta_max: float = VEHICLE_LIMITS.delta_max
    """Steering angle limit δ_max (rad); at most the vehicle's hard limit."""
    steer_rate_limit: float = VEHICLE_LIMITS.delta_rate_max
    """Steering rate limit δ̇_max (rad/s) of the angle reference and of the EPS rate command; at most the
    vehicle's road-wheel steering rate."""
    torque_max: float = VEHICLE_LIMITS.T_max
    """Motor torque limit T_max (N m); at most the vehicle's hard limit."""
    torque_rate_limit: float = VEHICLE_LIMITS.torque_rate_max
    """Torque rate limit Ṫ_max (N m/s); at most the vehicle's hard limit."""
    timeout: float = ECU_TIMEOUT
    """Age of the newest valid command after which the minimum-risk maneuver starts (s); at most the
    vehicle ECUs' own command timeout, so the bridge never keeps a dead controller's command alive longer."""
    maneuver: MinimumRiskParams = MinimumRiskParams()
    """The minimum-risk maneuver (:mod:`moose.minimum_risk`; the ``minimum_risk`` group of the configuration)."""

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            if f.name != "maneuver":
                check(f.name, getattr(self, f.name), _positive_finite, "a positive finite number")
        check("maneuver", self.maneuver, lambda v: isinstance(v, MinimumRiskParams), "a MinimumRiskParams")
        for name, limit_name in HARD_LIMIT.items():
            limit = getattr(VEHICLE_LIMITS, limit_name)
            check(name, getattr(self, name), at_most(limit),
                  f"at most the vehicle's hard limit {limit_name} = {limit:g} (configuration can only tighten it)")
        check("timeout", self.timeout, lambda v: v <= ECU_TIMEOUT,
              f"at most the vehicle ECUs' command timeout {ECU_TIMEOUT:g} s")

    @property
    def limits(self) -> ActuatorLimits:
        """The four limits, as every output of the guard respects them."""
        return ActuatorLimits(self.delta_max, self.steer_rate_limit, self.torque_max, self.torque_rate_limit)

    @property
    def brake_torque(self) -> float:
        """T_brake (N m per rear motor)."""
        return self.maneuver.brake_fraction * self.torque_max

    @classmethod
    def from_vehicle(cls, vehicle: VehicleParams, **changes: Any) -> "GuardParams":
        """The limits of ``vehicle`` (a :class:`~moose.params.VehicleParams`); other fields from ``changes`` or
        the defaults."""
        limits = {name: getattr(vehicle, limit_name) for name, limit_name in HARD_LIMIT.items()}
        return cls(**limits, **changes)


class GuardState(str, enum.Enum):
    IDLE = "idle"
    """No valid command yet: zero torque, steering held."""
    COMMANDING = "commanding"
    """Following a fresh valid command."""
    MINIMUM_RISK = "minimum_risk"
    """Commands lost: steering back to straight and braking."""
    STOPPED = "stopped"
    """The minimum-risk maneuver is complete: stopped, steering centred, zero torque."""


class _Arrival:
    """When an input arrived: the output count before it, and the caller-clock total at the first output after it."""

    __slots__ = ("cycle", "tau")

    def __init__(self, cycle: int) -> None:
        self.cycle = cycle
        self.tau: Optional[float] = None


class CommandGuard:
    """Limits, rate limits, end stops, the command timeout and the minimum-risk maneuver.

    ``period`` is T_cmd, the period of the command frames (from the DBC); :meth:`output` is called
    once per command frame.
    """

    def __init__(self, params: GuardParams = GuardParams(), period: float = 0.01) -> None:
        check("period", period, _positive_finite, "a positive finite command period (s)")
        if params.timeout < period:
            raise ParamError(f"timeout = {params.timeout!r} is invalid: expected at least one command period "
                             f"({period:g} s)")
        self.params = params
        self.period = float(period)
        self.state = GuardState.IDLE
        self.clamped = False
        """A limit, rate limit or end stop changed the last output."""
        self.invalid = 0
        """Invalid (non-finite or non-numeric) commands received."""
        self._latest: Optional[Command] = None
        self._command: Optional[_Arrival] = None
        self._angle: Optional[tuple[_Arrival, float]] = None
        self._wheels: Optional[tuple[_Arrival, float]] = None
        self._invalid_latched = False
        self._out = Command(0.0, 0.0, 0.0, 0.0)
        self._cycle = 0
        self._tau = 0.0
        self._t_last: Optional[float] = None
        self.limits = params.limits
        self.maneuver = MinimumRiskManeuver(params.maneuver, self.limits, self.period)
        """The minimum-risk maneuver (:mod:`moose.minimum_risk`), run when commands stop."""

    @property
    def timed_out(self) -> bool:
        """The last output was not a command being followed (idle, minimum-risk maneuver or stopped)."""
        return self.state != GuardState.COMMANDING

    def receive(self, command: Command) -> None:
        """A command from the motion controller; the newest one counts, whatever the clock says."""
        if not command.valid:
            self.invalid += 1
            self._invalid_latched = True
            self._latest = self._command = None
            return
        self._latest = Command(*(float(v) for v in dataclasses.astuple(command)))
        self._command = _Arrival(self._cycle)

    def observe_angle(self, delta: float) -> None:
        """The steering angle the EPS measured (EPS_STATUS): end stops, steering back, and the angle to hold
        when idle."""
        if not _finite(delta):
            return
        self._angle = (_Arrival(self._cycle), float(delta))
        if self._cycle == 0:  # the first output starts from the measured angle
            self._out = dataclasses.replace(self._out, steering_angle=_clip(float(delta), self.params.delta_max))

    def observe_wheel_speeds(self, omega_rl: float, omega_rr: float) -> None:
        """The rear wheel speeds (WHEEL_SPEEDS): braking in the minimum-risk maneuver."""
        if _finite(omega_rl) and _finite(omega_rr):
            self._wheels = (_Arrival(self._cycle), 0.5 * (float(omega_rl) + float(omega_rr)))

    def pop_invalid(self) -> bool:
        """An invalid command since the previous call (the status frame's flag)."""
        flag, self._invalid_latched = self._invalid_latched, False
        return flag

    def output(self, t: float) -> Command:
        """The command frame's content at ``t`` (the caller's monotonic time)."""
        self._advance(t)
        old = self._out
        if self._latest is not None and self._fresh(self._command):
            self.state = GuardState.COMMANDING
            self.maneuver.reset()
            want = self._latest
            out = self._limit(want, old)
            self.clamped = out != want
        else:
            self._latest = self._command = None
            if self.state == GuardState.COMMANDING:
                self.state = GuardState.MINIMUM_RISK
            if self.state == GuardState.IDLE:
                measured = self._measured_angle()
                target = Command(old.steering_angle if measured is None else measured, 0.0, 0.0, 0.0)
            else:
                wheels = self._wheels
                target = self.maneuver.target(old, self._measured_angle(),
                                              wheels[1] if wheels is not None and self._fresh(wheels[0]) else None)
                if self.maneuver.stopped:
                    self.state = GuardState.STOPPED
            out = self._limit(target, old)
            self.clamped = False
        self._out = out
        return out

    # -- internals ------------------------------------------------------------------------

    def _advance(self, t: float) -> None:
        """One output: count the cycle, add the caller clock's forward step, date the inputs that arrived."""
        self._cycle += 1
        if _finite(t):
            if self._t_last is not None and t > self._t_last:
                self._tau += t - self._t_last
            self._t_last = float(t)
        for arrival in (self._command, self._angle and self._angle[0], self._wheels and self._wheels[0]):
            if arrival is not None and arrival.tau is None:
                arrival.tau = self._tau

    def _age(self, arrival: _Arrival) -> float:
        """Age of an input (s): the larger of the cycle count and the caller clock's forward steps."""
        assert arrival.tau is not None
        return max((self._cycle - arrival.cycle - 1) * self.period, self._tau - arrival.tau)

    def _fresh(self, arrival: Optional[_Arrival]) -> bool:
        return arrival is not None and self._age(arrival) <= self.params.timeout + _TIME_EPS

    def _measured_angle(self) -> Optional[float]:
        return self._angle[1] if self._angle is not None and self._fresh(self._angle[0]) else None

    def _limit(self, want: Command, old: Command) -> Command:
        """``want`` clipped to the limits, rate-limited from ``old`` over one command period, end stops applied."""
        return self.limits.limit(want, old, self.period, self._measured_angle())


def _finite(value: object) -> bool:
    try:
        return isinstance(value, numbers.Real) and not isinstance(value, bool) and math.isfinite(value)
    except OverflowError:
        return False


def _clip(value: float, bound: float) -> float:
    return min(max(value, -bound), bound)
