"""The command guard to the cycle: its ages (cycles and the caller's clock), the rounding allowance of the timeout,
the flags of the status frame, the angle held while idle, the straight-ahead tolerance and the stop count."""
from __future__ import annotations

import pytest

from can_lockstep import commanding
from moose.canbus.safety import Command, CommandGuard, GuardParams, GuardState
from moose.params import ParamError

P = GuardParams()
DT = 0.01


@pytest.mark.parametrize("period", [0.0, -0.01, float("inf"), float("nan"), True])
def test_a_bad_command_period_is_refused(period: object) -> None:
    with pytest.raises(ParamError, match=r"^period = .* is invalid: expected a positive finite command period \(s\)$"):
        CommandGuard(P, period)  # type: ignore[arg-type]


@pytest.mark.parametrize("field", ["delta_max", "steer_rate_limit", "torque_max", "torque_rate_limit", "timeout"])
def test_every_limit_must_be_positive_and_the_timeout_within_the_ecus(field: str) -> None:
    with pytest.raises(ParamError, match=rf"^{field} = 0 is invalid: expected a positive finite number$"):
        GuardParams(**{field: 0})
    with pytest.raises(ParamError, match=r"^timeout = 0.06 is invalid: expected at most the vehicle ECUs' command "
                                         r"timeout 0.05 s$"):
        GuardParams(timeout=0.06)


def test_the_maneuver_parameters_must_be_a_parameter_group() -> None:
    with pytest.raises(ParamError, match=r"^maneuver = 'brake' is invalid: expected a MinimumRiskParams$"):
        GuardParams(maneuver="brake")  # type: ignore[arg-type]


def test_a_fresh_guard_reports_nothing() -> None:
    guard = CommandGuard(P)
    assert guard.state == GuardState.IDLE and guard.timed_out
    assert guard.clamped is False and guard.pop_invalid() is False and guard.invalid == 0


def test_every_invalid_command_is_counted_and_latched_once() -> None:
    guard = CommandGuard(P)
    guard.receive(Command(float("nan"), 0.0, 0.0, 0.0))
    guard.receive(Command(0.0, 0.0, float("inf"), 0.0))
    assert guard.invalid == 2 and guard.pop_invalid() is True and guard.pop_invalid() is False


def test_idle_and_the_minimum_risk_maneuver_are_never_reported_as_clamping() -> None:
    guard = CommandGuard(P)
    guard.observe_angle(0.0)
    guard.output(0.0)
    guard.observe_angle(0.2)  # the measured angle moves: the held reference follows it at the rate limit
    out = guard.output(0.01)
    assert out.steering_angle == pytest.approx(P.steer_rate_limit * DT) and guard.clamped is False
    t = commanding(guard, Command(0.3, 5.0, 200.0, 200.0), 3, 0.02)  # clamped while commanding
    assert guard.clamped is True
    for k in range(10):
        guard.output(t + k * DT)
    assert guard.state == GuardState.MINIMUM_RISK and guard.clamped is False


def test_a_caller_whose_ticks_come_late_ages_the_command_by_its_clock() -> None:
    """Three outputs 30 ms apart: two cycles by count (20 ms), 60 ms by the caller's clock — older than the timeout."""
    guard = CommandGuard(P)
    guard.receive(Command(0.0, 0.0, 50.0, 50.0))
    guard.output(0.0)
    guard.output(0.03)
    assert guard.state == GuardState.COMMANDING
    guard.output(0.06)
    assert guard.state == GuardState.MINIMUM_RISK


def test_the_timeout_allows_a_nanosecond_of_round_off() -> None:
    on_time, late = CommandGuard(P), CommandGuard(P)
    for guard, age in ((on_time, P.timeout + 1e-9), (late, P.timeout + 2e-9)):
        guard.receive(Command(0.0, 0.0, 10.0, 10.0))
        guard.output(0.0)
        guard.output(age)
    assert on_time.state == GuardState.COMMANDING and late.state == GuardState.MINIMUM_RISK


def lose_commands(guard: CommandGuard) -> float:
    """Command for 0.1 s, then fall silent; returns the time of the first output after the timeout."""
    t = commanding(guard, Command(0.0, 0.0, 0.0, 0.0), 10)
    for k in range(6):
        guard.output(t + k * DT)
    assert guard.state == GuardState.MINIMUM_RISK
    return t + 6 * DT


@pytest.mark.parametrize("measured, rate", [(0.003, 0.0), (0.005, 0.0), (-0.005, 0.0), (0.02, -0.4), (-0.03, 0.6)])
def test_steering_back_rests_within_the_straight_tolerance(measured: float, rate: float) -> None:
    """−K_δ δ_meas outside ±straight_tolerance (inclusive), 0 inside: the EPS does not chase sensor noise."""
    guard = CommandGuard(P)
    t = lose_commands(guard)
    guard.observe_angle(measured)
    assert guard.output(t).steering_rate == pytest.approx(rate, abs=1e-12)


def test_the_maneuver_stops_after_the_wheels_were_still_for_the_stop_time() -> None:
    """0.2 s of fresh wheel speeds within ±0.1 rad/s (inclusive): 20 outputs; a faster wheel restarts the count,
    so does a gap in the measurements."""
    def outputs_until_stopped(omegas: list) -> int:
        guard = CommandGuard(P)
        t = lose_commands(guard)
        for k, omega in enumerate(omegas):
            if omega is not None:
                guard.observe_wheel_speeds(omega, omega)
            guard.output(t + k * DT)
            if guard.state == GuardState.STOPPED:
                return k + 1
        return -1

    assert outputs_until_stopped([0.0] * 30) == 20
    assert outputs_until_stopped([P.maneuver.stop_speed] * 30) == 20  # exactly the stop speed counts as still
    assert outputs_until_stopped([0.0] * 10 + [0.5] + [0.0] * 30) == 31  # restarted after the eleventh
    assert outputs_until_stopped([0.0] * 10 + [None] * 7 + [0.0] * 30) == 37  # stale for 7: restarted
    guard = CommandGuard(P)  # a valid command in between also restarts it
    t = lose_commands(guard)
    for k in range(10):
        guard.observe_wheel_speeds(0.0, 0.0)
        guard.output(t + k * DT)
    t = commanding(guard, Command(0.0, 0.0, 0.0, 0.0), 1, t + 10 * DT)
    count = 0
    while guard.state != GuardState.STOPPED:
        guard.observe_wheel_speeds(0.0, 0.0)
        guard.output(t + count * DT)
        count += 1
    assert count == 5 + 20  # fresh for 5 more outputs (50 ms), then 20 still ones in the maneuver
