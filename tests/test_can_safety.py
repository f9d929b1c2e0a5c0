"""The bridge's command guard: the vehicle's limits, clock steps, hostile input and configuration, the minimum-risk
maneuver."""
from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from can_hostile import clock_step, hostile_guard_params, wild
from can_lockstep import commanding
from moose.canbus.safety import Command, CommandGuard, GuardParams, GuardState
from moose.params import VEHICLE_LIMITS, ParamError, VehicleParams
from moose.schema import MinimumRiskParams

P = GuardParams()
DT = 0.01
TOL = 1e-9


def assert_within_limits(out: Command, previous: Command, p: GuardParams, period: float) -> None:
    """Every limit, and every step from the previous output at most one command period at the limit rate."""
    values = (out.steering_angle, out.steering_rate, out.torque_rl, out.torque_rr)
    assert all(math.isfinite(v) for v in values)
    assert abs(out.steering_angle) <= p.delta_max + TOL
    assert abs(out.steering_rate) <= p.steer_rate_limit + TOL
    assert abs(out.torque_rl) <= p.torque_max + TOL and abs(out.torque_rr) <= p.torque_max + TOL
    assert abs(out.steering_angle - previous.steering_angle) <= p.steer_rate_limit * period + TOL
    assert abs(out.torque_rl - previous.torque_rl) <= p.torque_rate_limit * period + TOL
    assert abs(out.torque_rr - previous.torque_rr) <= p.torque_rate_limit * period + TOL


# -- the limits are the vehicle's ------------------------------------------------------------------


def test_limits_are_the_vehicles_hard_limits_and_configuration_can_only_tighten_them() -> None:
    assert (P.delta_max, P.steer_rate_limit, P.torque_max, P.torque_rate_limit) == (
        VEHICLE_LIMITS.delta_max, VEHICLE_LIMITS.delta_rate_max, VEHICLE_LIMITS.T_max, VEHICLE_LIMITS.torque_rate_max)
    tight = VehicleParams(delta_max=0.2, delta_rate_max=0.5, T_max=150.0, torque_rate_max=1000.0)
    g = GuardParams.from_vehicle(tight, timeout=0.03)
    assert ((g.delta_max, g.steer_rate_limit, g.torque_max, g.torque_rate_limit, g.timeout)
            == (0.2, 0.5, 150.0, 1000.0, 0.03))
    assert g.brake_torque == 150.0  # the braking torque follows the tightened T_max
    # looser than the vehicle: refused at start-up, naming the field and the value
    for field, value in (("delta_max", 0.5), ("delta_max", 3.0), ("torque_max", 300.0), ("steer_rate_limit", 2.0),
                         ("torque_rate_limit", 5000.0)):
        with pytest.raises(ParamError,
                           match=rf"{field} = {value!r} is invalid: expected at most the vehicle's hard limit"):
            GuardParams(**{field: value})
    with pytest.raises(ParamError, match="timeout = 0.5 is invalid"):
        GuardParams(timeout=0.5)  # longer than the vehicle ECUs' own 50 ms would keep a dead controller's command alive
    for field, value in (("timeout", 0.0), ("delta_max", float("nan"))):
        with pytest.raises(ParamError, match=rf"{field} = "):
            GuardParams(**{field: value})
    for field, value in (("brake_gain", float("inf")), ("stop_time", -1.0), ("brake_fraction", 1.5),
                         ("eps_gain", True)):
        with pytest.raises(ParamError, match=rf"{field} = "):  # the maneuver's own group (moose.minimum_risk)
            MinimumRiskParams(**{field: value})
    with pytest.raises(ParamError, match="timeout = 0.01 is invalid: expected at least one command period"):
        CommandGuard(GuardParams(timeout=0.01), period=0.02)


def test_the_steering_rate_is_one_fact_for_the_angle_reference_and_the_eps_rate_command() -> None:
    assert P.steer_rate_limit == VehicleParams().delta_rate_max == 1.0
    guard = CommandGuard(P)
    guard.output(0.0)
    guard.receive(Command(0.3, 50.0, 0.0, 0.0))
    out = guard.output(DT)
    assert out.steering_rate == VehicleParams().delta_rate_max  # the EPS rate command
    assert out.steering_angle == pytest.approx(VehicleParams().delta_rate_max * DT)  # the angle reference's step


# -- clock steps -----------------------------------------------------------------------------------


def test_a_forward_clock_step_does_not_widen_the_rate_limits() -> None:
    guard = CommandGuard(P)
    t = commanding(guard, Command(0.0, 0.0, 0.0, 0.0), 20, 100.0)
    guard.receive(Command(0.3, 1.0, 200.0, 200.0))
    out = guard.output(t + 1.0)  # the clock steps +1 s between two frames
    assert guard.state == GuardState.COMMANDING  # the command arrived after the step: fresh
    assert out.steering_angle == pytest.approx(P.steer_rate_limit * DT)  # 0.01 rad, not 0.3
    assert out.torque_rl == pytest.approx(P.torque_rate_limit * DT)  # 20 N m, not 200


def test_a_forward_clock_step_ages_a_command_that_arrived_before_it() -> None:
    guard = CommandGuard(P)
    t = commanding(guard, Command(0.1, 0.0, 100.0, 100.0), 20, 0.0)
    guard.output(t + 1.0)  # nothing new since the step: the newest command is 1 s old on this clock
    assert guard.state == GuardState.MINIMUM_RISK


def test_a_backward_clock_step_neither_freezes_the_command_nor_disables_the_timeout() -> None:
    guard = CommandGuard(P)
    t = commanding(guard, Command(0.2, 0.5, 150.0, 150.0), 40, 10.0)
    # new commands after a -5 s step are followed
    t = commanding(guard, Command(0.0, 0.0, 0.0, 0.0), 30, t - 5.0)
    out = guard.output(t)
    assert out.steering_angle == pytest.approx(0.0, abs=1e-12) and out.torque_rl == pytest.approx(0.0, abs=1e-9)
    # the controller dies at a -5 s step: the timeout still fires within timeout + one cycle
    guard = CommandGuard(P)
    t = commanding(guard, Command(0.2, 0.5, 150.0, 150.0), 40, 10.0) - 5.0
    states = []
    for k in range(10):
        guard.output(round(t + k * DT, 9))
        states.append(guard.state)
    limit = int(round(P.timeout / DT))  # 5 cycles of a 50 ms timeout
    assert states[:limit] == [GuardState.COMMANDING] * limit and GuardState.MINIMUM_RISK in states[limit:limit + 1]


def test_a_stopped_clock_does_not_disable_the_timeout() -> None:
    guard = CommandGuard(P)
    commanding(guard, Command(0.2, 0.5, 150.0, 150.0), 10, 1.0)
    states = []
    for _ in range(8):
        guard.output(1.0)  # the same time over and over
        states.append(guard.state)
    assert states[5] == GuardState.MINIMUM_RISK


# -- hostile input, clocks and configuration (property-based) ---------------------------------------

@st.composite
def hostile_params(draw: st.DrawFn) -> tuple[GuardParams, float]:
    """Any configuration that passes validation, and a command period it accepts."""
    period = draw(st.sampled_from([0.001, 0.01, 0.02]))
    return draw(hostile_guard_params(timeout_min=period)), period


@settings(max_examples=400, deadline=None)
@given(hostile_params(),
       st.lists(st.tuples(clock_step, st.one_of(st.none(), st.tuples(wild, wild, wild, wild)),
                          st.one_of(st.none(), wild), st.one_of(st.none(), st.tuples(wild, wild))),
                min_size=1, max_size=80))
def test_any_input_any_clock_any_valid_config_stays_inside_the_limits_and_times_out(config: tuple,
                                                                                     stream: list) -> None:
    p, period = config
    guard = CommandGuard(p, period)
    t, previous = 0.0, guard.output(0.0)
    since_command = None  # outputs since the newest valid command arrived
    for step, command, angle, wheels in stream:
        t = t + step
        fresh = False
        if command is not None:
            guard.receive(Command(*command))
            fresh = Command(*command).valid
            since_command = 0 if fresh else None
        if angle is not None:
            guard.observe_angle(angle)
        if wheels is not None:
            guard.observe_wheel_speeds(*wheels)
        out = guard.output(t)
        assert_within_limits(out, previous, p, period)  # whatever the clock did
        if since_command is not None:
            since_command += 1
        if fresh:  # a command that arrived since the previous frame is followed, whatever the clock did
            assert guard.state == GuardState.COMMANDING
        if guard.state == GuardState.COMMANDING:  # never older than the timeout in command cycles
            assert since_command is not None and (since_command - 1) * period <= p.timeout + 1e-9
        else:
            assert abs(out.steering_angle) <= abs(previous.steering_angle) + TOL or guard.state == GuardState.IDLE
        if isinstance(angle, float) and math.isfinite(angle):  # never towards an end stop that is reached
            if angle >= p.delta_max:
                assert out.steering_rate <= TOL
            if angle <= -p.delta_max:
                assert out.steering_rate >= -TOL
            assert abs(angle + out.steering_rate * period) <= max(p.delta_max, abs(angle)) + TOL
        previous = out


# -- following, invalid commands, idle ---------------------------------------------------------------


def test_a_valid_command_is_followed_at_the_rate_limits() -> None:
    guard = CommandGuard(P)
    guard.output(0.0)
    outs = []
    for k in range(1, 60):
        guard.receive(Command(0.25, 0.8, 150.0, -150.0))
        outs.append(guard.output(DT * k))
    # angle ramps at δ̇_max (0.01 rad per cycle) up to 0.25; torques at Ṫ_max (20 N m per cycle) up to ±150
    assert [round(o.steering_angle, 9) for o in outs[:3]] == [0.01, 0.02, 0.03]
    assert outs[23].steering_angle == pytest.approx(0.24) and outs[24].steering_angle == pytest.approx(0.25)
    assert outs[0].torque_rl == pytest.approx(20.0) and outs[0].torque_rr == pytest.approx(-20.0)
    assert outs[-1] == Command(0.25, 0.8, 150.0, -150.0) and not guard.clamped and not guard.timed_out
    guard.receive(Command(1.0, 50.0, 1e6, 0.0))
    out = guard.output(0.6)
    assert out.steering_angle == pytest.approx(0.26) and out.steering_rate == P.steer_rate_limit
    assert out.torque_rl == pytest.approx(170.0) and guard.clamped


def test_an_invalid_command_starts_the_minimum_risk_maneuver_at_once_and_a_valid_one_recovers_rate_limited() -> None:
    guard = CommandGuard(P)
    for k in range(0, 30):
        guard.receive(Command(0.1, 0.5, 100.0, 100.0))
        before = guard.output(DT * k)
    assert before == Command(0.1, 0.5, 100.0, 100.0)
    guard.receive(Command(0.1, float("nan"), 100.0, 100.0))
    out = guard.output(0.30)
    assert guard.state == GuardState.MINIMUM_RISK and guard.invalid == 1
    assert guard.pop_invalid() and not guard.pop_invalid()
    assert out.steering_angle == pytest.approx(0.09) and out.torque_rl == pytest.approx(80.0)  # back towards 0
    guard.output(0.31)
    guard.receive(Command(-0.2, 0.5, 100.0, 100.0))
    out = guard.output(0.32)
    assert guard.state == GuardState.COMMANDING
    assert out.torque_rl == pytest.approx(80.0)  # 60 after two maneuver cycles, +20 rate-limited
    assert out.steering_angle == pytest.approx(0.07)  # 0.08 after two cycles, then towards -0.2 at δ̇_max


def test_idle_holds_the_measured_angle_with_zero_torque_and_never_brakes() -> None:
    guard = CommandGuard(P)
    guard.observe_angle(-0.12)
    guard.observe_wheel_speeds(20.0, 20.0)
    out = guard.output(0.0)
    assert out == Command(-0.12, 0.0, 0.0, 0.0) and guard.state == GuardState.IDLE
    for k in range(1, 50):
        guard.observe_angle(-0.12)
        guard.observe_wheel_speeds(20.0, 20.0)
        out = guard.output(DT * k)
    assert out == Command(-0.12, 0.0, 0.0, 0.0) and guard.state == GuardState.IDLE  # no command ever: no maneuver


def test_end_stops_use_a_fresh_measurement_only() -> None:
    guard = CommandGuard(P)
    guard.output(0.0)
    guard.observe_angle(0.5)  # beyond the end stop: the EPS may only steer back
    guard.receive(Command(0.3, 1.0, 0.0, 0.0))
    assert guard.output(0.01).steering_rate == 0.0
    guard.receive(Command(0.3, -1.0, 0.0, 0.0))
    assert guard.output(0.02).steering_rate == -1.0
    guard.observe_angle(0.295)  # 5 mrad from the stop: at most 0.5 rad/s outwards for one 10 ms cycle
    guard.receive(Command(0.3, 1.0, 0.0, 0.0))
    assert guard.output(0.03).steering_rate == pytest.approx(0.5)
    for k in range(4, 20):
        guard.receive(Command(0.3, 1.0, 0.0, 0.0))
        out = guard.output(DT * k)
    assert out.steering_rate == 1.0  # the measurement is stale: no end-stop cut


# -- the minimum-risk maneuver ---------------------------------------------------------------------


def test_lost_commands_steer_back_to_straight_and_brake_to_a_stop() -> None:
    guard = CommandGuard(P)
    t = commanding(guard, Command(0.3, 0.0, 100.0, 100.0), 40, 0.0)
    delta, omega, outs = 0.3, 23.0, []
    for k in range(400):
        guard.observe_angle(delta)
        guard.observe_wheel_speeds(omega, omega)
        out = guard.output(round(t + k * DT, 9))
        outs.append((guard.state, out))
        delta = max(delta + out.steering_rate * DT, 0.0)  # an EPS following its rate command
        omega = omega + out.torque_rl / 21.5 * DT  # both motors on the car's inertia seen by a wheel, m r² / 2 + J
    states = [s for s, _ in outs]
    assert states[:5] == [GuardState.COMMANDING] * 5 and states[5] == GuardState.MINIMUM_RISK
    maneuver = [o for s, o in outs if s == GuardState.MINIMUM_RISK]
    assert maneuver[0].steering_rate == -P.steer_rate_limit  # -K_δ·0.3 = -6 rad/s, clipped to δ̇_max
    assert [round(o.steering_angle, 9) for o in maneuver[:3]] == [0.29, 0.28, 0.27]  # the reference ramps to 0
    assert all(o.torque_rl == o.torque_rr for o in maneuver)  # no yaw moment
    torques = [o.torque_rl for o in maneuver]
    assert torques[:3] == pytest.approx([80.0, 60.0, 40.0]) and min(torques) == pytest.approx(-P.brake_torque)
    assert maneuver[-1].steering_angle == pytest.approx(0.0, abs=1e-12) and abs(maneuver[-1].steering_rate) < 0.05
    stopped = states.index(GuardState.STOPPED)
    assert 2.4 < stopped * DT < 3.5  # 23 rad/s at T_brake (about 2.4 s), the slowing under k_ω, 0.2 s still
    assert abs(omega) < P.maneuver.stop_speed
    assert outs[stopped + 2][1].torque_rl == 0.0  # released, ramped to 0 at Ṫ_max
    assert all(s == GuardState.STOPPED for s in states[stopped:])


def test_braking_falls_with_the_wheel_speed_and_needs_a_fresh_measurement() -> None:
    guard = CommandGuard(P)
    t = commanding(guard, Command(0.0, 0.0, 0.0, 0.0), 10, 0.0)
    for k in range(30):
        guard.observe_wheel_speeds(0.5, 0.7)  # 0.6 rad/s: k_ω·ω̄ = 90 N m < T_brake
        out = guard.output(t + k * DT)
    assert out.torque_rl == pytest.approx(-P.maneuver.brake_gain * 0.6)
    for k in range(30, 60):  # the wheel speeds stop arriving: no blind braking
        out = guard.output(t + k * DT)
    assert out.torque_rl == 0.0 and guard.state == GuardState.MINIMUM_RISK
    guard = CommandGuard(P)
    t = commanding(guard, Command(0.0, 0.0, 0.0, 0.0), 10, 0.0)
    for k in range(30):
        guard.observe_wheel_speeds(-2.0, -2.0)  # rolling backwards: the braking torque is positive
        out = guard.output(t + k * DT)
    assert out.torque_rl == pytest.approx(P.brake_torque)


def test_without_an_angle_measurement_the_eps_follows_the_reference_ramp() -> None:
    guard = CommandGuard(P)
    t = commanding(guard, Command(0.05, 0.0, 0.0, 0.0), 20, 0.0)
    rates = []
    for k in range(12):
        out = guard.output(t + k * DT)
        rates.append(round(out.steering_rate, 9))
    assert rates[5:10] == [-1.0] * 5 and rates[10:] == [0.0, 0.0]  # 0.05 rad at 1 rad/s: 5 cycles
