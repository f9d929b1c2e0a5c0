"""The bridge's command guard: limits, rate limits, end stops, invalid commands, timeout and recovery."""
from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from moose.canbus.safety import Command, CommandGuard, GuardParams
from moose.params import ParamError, VehicleParams

P = GuardParams()
DT = 0.01
TOL = 1e-9

wild = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.floats(-1e3, 1e3), st.sampled_from([0.0, 0.3, -0.3]))


def assert_within_limits(out: Command, previous: Command, dt: float, p: GuardParams = P) -> None:
    values = (out.steering_angle, out.steering_rate, out.torque_rl, out.torque_rr)
    assert all(math.isfinite(v) for v in values)
    assert abs(out.steering_angle) <= p.delta_max + TOL
    assert abs(out.steering_rate) <= p.steer_rate_limit + TOL
    assert abs(out.torque_rl) <= p.torque_max + TOL and abs(out.torque_rr) <= p.torque_max + TOL
    assert abs(out.steering_angle - previous.steering_angle) <= p.steer_rate_limit * dt + TOL
    assert abs(out.torque_rl - previous.torque_rl) <= p.torque_rate_limit * dt + TOL
    assert abs(out.torque_rr - previous.torque_rr) <= p.torque_rate_limit * dt + TOL


def test_defaults_come_from_table_one_and_parameters_are_checked() -> None:
    assert (P.delta_max, P.torque_max) == (0.3, 200.0)
    assert GuardParams.from_vehicle(VehicleParams(T_max=150.0), timeout=0.1).torque_max == 150.0
    with pytest.raises(ParamError, match="steer_rate_limit = -1.0"):
        GuardParams(steer_rate_limit=-1.0)
    with pytest.raises(ParamError, match="timeout = 0.0"):
        GuardParams(timeout=0.0)
    with pytest.raises(ParamError, match="safe_steering = 'drift'"):
        GuardParams(safe_steering="drift")


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(wild, wild, wild, wild, st.booleans(), st.one_of(st.none(), wild)), min_size=1, max_size=80),
       st.sampled_from(["hold", "center"]), st.sampled_from([0.01, 0.004, 0.023]))
def test_random_command_streams_never_leave_the_limits(stream: list, safe_steering: str, dt: float) -> None:
    p = GuardParams(safe_steering=safe_steering)
    guard = CommandGuard(p)
    previous = guard.output(0.0)
    for k, (angle, rate, t_rl, t_rr, send, measured) in enumerate(stream, start=1):
        t = dt * k
        if send:
            guard.receive(Command(angle, rate, t_rl, t_rr), t)
        if measured is not None:
            guard.observe_angle(measured, t)
        out = guard.output(t)
        assert_within_limits(out, previous, dt, p)
        if measured is not None and math.isfinite(measured):  # never towards an end stop that is reached
            if measured >= p.delta_max:
                assert out.steering_rate <= TOL
            if measured <= -p.delta_max:
                assert out.steering_rate >= -TOL
            assert abs(measured + out.steering_rate * p.command_period) <= max(p.delta_max, abs(measured)) + TOL
        previous = out


def test_a_valid_command_is_followed_at_the_rate_limits() -> None:
    guard = CommandGuard(P)
    guard.output(0.0)
    outs = []
    for k in range(1, 60):
        guard.receive(Command(0.25, 0.8, 150.0, -150.0), DT * k)
        outs.append(guard.output(DT * k))
    # angle ramps at δ̇_lim (0.02 rad per cycle) up to 0.25; torques at Ṫ_lim (20 N m per cycle) up to ±150
    assert [round(o.steering_angle, 9) for o in outs[:3]] == [0.02, 0.04, 0.06]
    assert outs[11].steering_angle == pytest.approx(0.24) and outs[12].steering_angle == pytest.approx(0.25)
    assert outs[0].torque_rl == pytest.approx(20.0) and outs[0].torque_rr == pytest.approx(-20.0)
    assert outs[-1] == Command(0.25, 0.8, 150.0, -150.0) and not guard.clamped and not guard.timed_out
    guard.receive(Command(1.0, 50.0, 1e6, 0.0), 0.6)
    out = guard.output(0.6)
    assert out.steering_angle == pytest.approx(0.27) and out.steering_rate == P.steer_rate_limit
    assert out.torque_rl == pytest.approx(170.0) and guard.clamped


def test_an_invalid_command_sends_the_safe_state_at_once_and_a_valid_one_recovers_rate_limited() -> None:
    guard = CommandGuard(P)
    for k in range(0, 30):
        guard.receive(Command(0.1, 0.5, 100.0, 100.0), DT * k)
        before = guard.output(DT * k)
    assert before == Command(0.1, 0.5, 100.0, 100.0)
    guard.receive(Command(0.1, float("nan"), 100.0, 100.0), 0.30)
    out = guard.output(0.30)
    assert guard.timed_out and guard.invalid == 1 and guard.pop_invalid() and not guard.pop_invalid()
    assert out.steering_angle == 0.1 and out.steering_rate == 0.0 and out.torque_rl == pytest.approx(80.0)
    guard.output(0.31)
    guard.receive(Command(-0.2, 0.5, 100.0, 100.0), 0.32)
    out = guard.output(0.32)
    assert not guard.timed_out
    assert out.torque_rl == pytest.approx(80.0)  # 60 after two safe cycles, +20 rate-limited
    assert out.steering_angle == pytest.approx(0.08)  # from the held 0.1 at δ̇_lim


@pytest.mark.parametrize("period", [0.01, 0.007])
def test_timeout_sends_the_safe_state_within_one_command_cycle_of_the_deadline(period: float) -> None:
    guard = CommandGuard(P)
    last_command = 0.2
    safe_at = None
    k = 0
    while True:
        t = round(period * k, 9)
        if t <= last_command:
            guard.receive(Command(0.2, 0.3, 120.0, 120.0), t)
        out = guard.output(t)
        if t <= last_command + P.timeout:
            assert not guard.timed_out
        elif safe_at is None:
            safe_at, first = t, out
        if safe_at is not None and t > safe_at + 0.2:
            break
        k += 1
    assert safe_at is not None and safe_at <= last_command + P.timeout + period + 1e-9
    assert first.steering_rate == 0.0 and first.torque_rl < 120.0
    assert out == Command(pytest.approx(0.2), 0.0, 0.0, 0.0)  # steering held, torque ramped to zero (≤ 0.06 s)


def test_center_option_returns_the_steering_to_straight_at_the_rate_limit() -> None:
    guard = CommandGuard(GuardParams(safe_steering="center"))
    outs = []
    for k in range(0, 60):
        t = round(DT * k, 9)
        if t <= 0.2:
            guard.receive(Command(0.3, 0.0, 0.0, 0.0), t)
        outs.append((t, guard.output(t), guard.timed_out))
    held = [(o, safe) for t, o, safe in outs if 0.15 <= t <= 0.25]  # commanded, then within the timeout
    assert len(held) == 11 and all(o.steering_angle == pytest.approx(0.3) and not safe for o, safe in held)
    ramp = [o for t, o, safe in outs if safe and t > 0.25]
    angles = [0.3] + [o.steering_angle for o in ramp]
    steps = [b - a for a, b in zip(angles[:-1], angles[1:])]
    assert steps[:15] == pytest.approx([-P.steer_rate_limit * DT] * 15)  # 0.3 rad in 15 cycles at 2 rad/s
    assert all(o.steering_rate == pytest.approx(-P.steer_rate_limit) for o in ramp[:15])
    assert all(o.steering_angle == pytest.approx(0.0, abs=1e-12) and o.steering_rate == 0.0 for o in ramp[15:])


def test_initial_angle_to_hold_is_the_measured_one() -> None:
    guard = CommandGuard(P)
    guard.observe_angle(-0.12, 0.0)
    out = guard.output(0.0)
    assert out.steering_angle == pytest.approx(-0.12) and out.steering_rate == 0.0 and guard.timed_out
    guard.observe_angle(0.5, 0.01)  # beyond the end stop: the EPS may only steer back
    guard.receive(Command(0.3, 2.0, 0.0, 0.0), 0.01)
    assert guard.output(0.01).steering_rate == 0.0
    guard.receive(Command(0.3, -2.0, 0.0, 0.0), 0.02)
    assert guard.output(0.02).steering_rate == -2.0
    guard.observe_angle(0.295, 0.03)  # 5 mrad from the stop: at most 0.5 rad/s outwards for one 10 ms cycle
    guard.receive(Command(0.3, 2.0, 0.0, 0.0), 0.03)
    assert guard.output(0.03).steering_rate == pytest.approx(0.5)
    guard.receive(Command(0.3, 2.0, 0.0, 0.0), 0.2)  # the measurement is stale: no end-stop cut
    assert guard.output(0.2).steering_rate == 2.0
