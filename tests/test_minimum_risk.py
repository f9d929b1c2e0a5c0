"""The minimum-risk maneuver is one law (moose.minimum_risk), and the CAN bridge's guard, the simulator's topic
I/O and the motion controller run it; against the plant it steers back to straight and stops."""
from __future__ import annotations

import dataclasses
import inspect
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from moose.canbus.safety import CommandGuard, GuardParams, GuardState
from moose.config import load_config
from moose.minimum_risk import ActuatorLimits, Command, MinimumRiskManeuver
from moose.params import ParamError, VehicleParams
from moose.schema import MINIMUM_RISK_BOUNDS, MinimumRiskParams
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


# -- hard bounds: configuration may choose within them, never disarm the fallback

BOUNDS = [(f.name, *getattr(MINIMUM_RISK_BOUNDS, f.name)) for f in dataclasses.fields(MinimumRiskParams)]


@pytest.mark.parametrize(("name", "low", "high"), BOUNDS, ids=[b[0] for b in BOUNDS])
def test_every_parameter_of_the_maneuver_has_hard_bounds(name: str, low: float, high: float) -> None:
    default = getattr(MinimumRiskParams(), name)
    assert low <= default <= high
    MinimumRiskParams(**{name: high})
    with pytest.raises(ParamError, match=rf"{name} = .* is invalid: expected .*hard bound.* of the minimum-risk"):
        MinimumRiskParams(**{name: high * 1.001})
    if low > 0:
        MinimumRiskParams(**{name: low})
        with pytest.raises(ParamError, match=rf"{name} = .* is invalid: expected a value in \[{low:g}, {high:g}\]"):
            MinimumRiskParams(**{name: low * 0.999})
    with pytest.raises(ParamError, match=rf"{name} = 0.0 is invalid"):
        MinimumRiskParams(**{name: 0.0})


@pytest.mark.parametrize("value", ["minimum_risk.brake_gain=1.0e+12", "minimum_risk.eps_gain=1.0e+12",
                                   "minimum_risk.stop_time=1.0e+9"])
def test_the_bridge_refuses_a_maneuver_that_would_not_stop_the_car(value: str) -> None:
    """The probe: ``moose node can_bridge`` accepted brake and EPS gains of 1e12 and a stop time of 1e9."""
    out = subprocess.run([sys.executable, "-m", "moose.cli", "node", "can_bridge", "--param", value],
                         capture_output=True, text=True, timeout=120)
    name = value.split("=")[0]
    assert out.returncode == 2 and f"can_bridge.{name} = " in out.stderr and "hard bounds" in out.stderr, out.stderr
    assert "started" not in out.stdout + out.stderr


def test_a_file_cannot_switch_off_the_safe_stop(tmp_path: Path) -> None:
    """The probe: ``minimum_risk: {stop_speed: 1000.0, straight_tolerance: 1000.0}`` was accepted, and with the
    observer killed the car left the field at 5 m/s."""
    path = tmp_path / "hostile.yaml"
    path.write_text("/**:\n  ros__parameters:\n    minimum_risk: {stop_speed: 1000.0, straight_tolerance: 1000.0}\n")
    for command in (["simulate", "--no-bag", "--duration", "0.5"], ["launch", "--no-bag"]):
        out = subprocess.run([sys.executable, "-m", "moose.cli", *command, "--config", str(path)],
                             capture_output=True, text=True, timeout=120)
        assert out.returncode == 2 and "minimum_risk.stop_speed = 1000.0 is invalid: expected at most 0.3, the hard " \
            "bound of the minimum-risk maneuver" in out.stderr, out.stderr


def stop(params: MinimumRiskParams, v0: float = 7.0, delta0: float = 0.3) -> dict[str, np.ndarray]:
    """The law alone against the plant from ``v0`` at steering angle ``delta0`` (fresh EPS angle and wheel speeds):
    12 s of the car's x, y, heading, v_x and δ, and when the law counted the car stopped."""
    config = load_config()
    plant = VehiclePlant(config.vehicle, dt=config.simulation.plant_dt)
    state = initial_state(config.vehicle, x=0.0, vx=v0)
    state[8] = delta0
    plant.reset(state)
    law = MinimumRiskManeuver(params, ActuatorLimits.from_vehicle(config.vehicle), DT)
    out, rows, stopped = Command(delta0, 0.0, 0.0, 0.0), [], np.nan
    for k in range(1200):
        s = plant.state
        out = law.step(out, float(s[8]), 0.5 * float(s[6] + s[7]))
        plant.step(np.array([out.steering_rate, out.torque_rl, out.torque_rr]),
                   config.simulation.plant_steps_per_motion)
        rows.append([(k + 1) * DT, *plant.state[[0, 1, 2, 3, 8]]])
        if law.stopped and np.isnan(stopped):
            stopped = (k + 1) * DT
    t, x, y, theta, vx, delta = np.array(rows).T
    return {"t": t, "x": x, "y": y, "theta": theta, "vx": vx, "delta": delta, "stopped": np.array(stopped)}


def test_at_its_weakest_the_maneuver_still_steers_straight_and_stops() -> None:
    """From 7 m/s at full lock with the most permissive values the bounds accept: straight within 0.5 s, a stop
    within the distance the lowest T_brake allows, the heading turned by little more than the default's, and what
    is left once the torque is released below 0.1 m/s (the bound's 0.3 rad/s at Table I's r)."""
    vehicle = VehicleParams()
    weakest, default = stop(MinimumRiskParams(**MINIMUM_RISK_BOUNDS.weakest())), stop(MinimumRiskParams())
    tolerance = MINIMUM_RISK_BOUNDS.straight_tolerance[1]
    straight = weakest["t"][np.argmax(np.abs(weakest["delta"]) <= tolerance)]
    assert straight < 0.5
    decel = 2 * MINIMUM_RISK_BOUNDS.brake_fraction[0] * vehicle.T_max / (vehicle.r * vehicle.m + 2 * vehicle.J_wr
                                                                         / vehicle.r)
    distance = float(np.hypot(weakest["x"][-1], weakest["y"][-1]))
    assert np.isfinite(weakest["stopped"]) and distance < 7.0**2 / (2 * decel) + 2.0
    assert abs(weakest["theta"][-1]) < abs(default["theta"][-1]) + 0.3
    assert 0.0 <= weakest["vx"][-1] < MINIMUM_RISK_BOUNDS.stop_speed[1] * vehicle.r + 0.005 < 0.1


def test_at_its_stiffest_gains_the_maneuver_neither_reverses_nor_oversteers() -> None:
    """k_ω and K_δ at their upper bounds: the braking on one period old wheel speeds never drives the car backwards,
    and the steering does not swing through straight ahead."""
    run = stop(MinimumRiskParams(brake_gain=MINIMUM_RISK_BOUNDS.brake_gain[1],
                                 eps_gain=MINIMUM_RISK_BOUNDS.eps_gain[1]))
    assert np.isfinite(run["stopped"]) and float(np.min(run["vx"])) >= 0.0
    assert float(np.min(run["delta"])) >= -MinimumRiskParams().straight_tolerance
