"""The minimum-risk maneuver is one law (moose.minimum_risk), and the CAN bridge's guard, the simulator's topic
I/O and the motion controller run it; against the plant it steers back to straight and stops."""
from __future__ import annotations

import inspect

import numpy as np
import pytest

from moose.canbus.safety import CommandGuard, GuardParams, GuardState
from moose.config import load_config
from moose.minimum_risk import ActuatorLimits, Command, MinimumRiskManeuver
from moose.params import VehicleParams
from moose.schema import MinimumRiskParams
from moose.vehicle import VehiclePlant, initial_state

DT = 0.01
LIMITS = ActuatorLimits.from_vehicle(VehicleParams())


def test_the_law_never_holds_the_steering_angle_and_brakes_with_the_wheel_speed() -> None:
    law = MinimumRiskManeuver(MinimumRiskParams(), LIMITS, DT)
    old = Command(0.2, 0.5, 150.0, 150.0)  # mid-maneuver: steering left, driving
    out = law.step(old, measured_angle=0.2, wheel_speed=20.0)
    assert out.steering_angle == pytest.approx(0.19)  # the reference ramps back at δ̇_max
    assert out.steering_rate == -LIMITS.steer_rate_limit  # −K_δ·0.2 = −4 rad/s, clipped to δ̇_max
    assert out.torque_rl == out.torque_rr == pytest.approx(150.0 - LIMITS.torque_rate_limit * DT)  # rate-limited
    for _ in range(50):
        out = law.step(out, measured_angle=0.2, wheel_speed=20.0)
    assert out.torque_rl == -law.brake_torque  # full regenerative braking at speed
    out = law.step(out, measured_angle=0.2, wheel_speed=None)  # no fresh wheel speed: no blind braking
    assert law.target(out, 0.2, None).torque_rl == 0.0
    assert law.target(out, 0.004, 1.0).steering_rate == 0.0  # straight within the tolerance: the EPS rests


def test_a_new_maneuver_counts_the_standstill_from_its_first_output() -> None:
    """A car already standing when the maneuver starts: the stop time (0.2 s) is 20 outputs, not 19."""
    maneuver = MinimumRiskManeuver(MinimumRiskParams(), LIMITS, DT)
    assert maneuver.stopped is False
    old = Command(0.0, 0.0, 0.0, 0.0)
    for k in range(1, 21):
        assert not maneuver.stopped, k
        old = maneuver.step(old, 0.0, 0.0)
    assert maneuver.stopped is True
    maneuver.reset()
    assert maneuver.stopped is False


def test_the_guard_runs_the_same_law() -> None:
    """The guard's maneuver is moose.minimum_risk's, step for step (not a copy of it)."""
    import moose.canbus.safety as safety

    assert "brake_gain" not in inspect.getsource(safety)  # the law's parameters live in one place
    params = GuardParams()
    guard = CommandGuard(params, DT)
    law = MinimumRiskManeuver(params.maneuver, params.limits, DT)
    guard.observe_angle(0.1)
    guard.receive(Command(0.1, 0.0, 100.0, 100.0))
    out = guard.output(0.0)
    t = 0.0
    for k in range(400):  # commands stop: five cycles later the maneuver runs
        t += DT
        angle, omega = 0.1 * max(0.0, 1.0 - k / 50), 20.0 * max(0.0, 1.0 - k / 300)
        guard.observe_angle(angle)
        guard.observe_wheel_speeds(omega, omega)
        previous, out = out, guard.output(t)
        if guard.state in (GuardState.MINIMUM_RISK, GuardState.STOPPED):
            assert out == law.step(previous, angle, omega)
    assert guard.state == GuardState.STOPPED and law.stopped


def test_against_the_plant_the_car_steers_straight_and_stops_inside_a_lane_change() -> None:
    """From 6 m/s with 0.15 rad of steering, the law alone (fresh EPS angle and wheel speeds from the plant):
    the wheels are straight within 0.5 s, the car stops within the distance T_brake allows, the heading
    changes little and the yaw rate dies out (holding the angle would drive a circle)."""
    config = load_config()
    vehicle = config.vehicle
    plant = VehiclePlant(vehicle, dt=config.simulation.plant_dt)
    state = initial_state(vehicle, x=0.0, vx=6.0)
    state[8] = 0.15  # δ
    plant.reset(state)
    law = MinimumRiskManeuver(config.minimum_risk, ActuatorLimits.from_vehicle(vehicle), DT)
    out = Command(0.15, 0.0, 0.0, 0.0)
    steps = config.simulation.plant_steps_per_motion
    straight_at = None
    for k in range(1500):
        s = plant.state
        out = law.step(out, float(s[8]), 0.5 * float(s[6] + s[7]))
        plant.step(np.array([out.steering_rate, out.torque_rl, out.torque_rr]), steps)
        if straight_at is None and abs(plant.state[8]) < 0.005:
            straight_at = (k + 1) * DT
        if law.stopped:
            break
    s = plant.state
    assert straight_at is not None and straight_at < 0.5
    assert law.stopped and abs(s[3]) < 0.05
    # T_brake = T_max on both rear wheels: a ≥ 2 T_max / (r m) ≈ 1.44 m/s², so at most v²/2a ≈ 12.5 m (+ ramps)
    assert np.hypot(s[0], s[1]) < 6.0**2 / (2 * 2 * vehicle.T_max / (vehicle.r * vehicle.m)) + 2.0
    assert abs(s[2]) < 0.3 and abs(s[5]) < 0.01
