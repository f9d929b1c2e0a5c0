"""Bridge ↔ virtual bus ↔ ECU emulator ↔ the real plant and sensors, in one process (lockstep, simulated time).

A feedback EPS law (the motion controller's, δ̇_cmd = 20 (δ* − δ_meas)) closes the steering loop
through the bus: commands leave as frames, the EPS angle comes back as frames.  When the
commands stop, the bridge's minimum-risk maneuver must bring the car to a stop, steering
straight, yaw stable, within the distance its braking torque allows.
"""
from __future__ import annotations

import math
from collections import Counter
from typing import Callable

import numpy as np
import pytest

from can_lockstep import Feedback, drive_over_can
from moose.canbus.codec import default_database
from moose.canbus.ecu import VehicleEcu
from moose.canbus.safety import Command, GuardParams, GuardState
from moose.params import VehicleParams
from moose.schema import SensorParams
from moose.signals import GpsSample, ImuSample, WheelSpeedSample
from moose.vehicle import (
    DELTA,
    GAMMA,
    OMEGA_RL,
    OMEGA_RR,
    THETA,
    VX,
    VY,
    X,
    Y,
)

pytestmark = [pytest.mark.can]

DT = 0.01
STOP = 1.2
"""The motion controller falls silent here."""


@pytest.fixture(scope="module")
def run() -> dict:
    vehicle = VehicleParams()
    guard = GuardParams.from_vehicle(vehicle)

    def controller(t: float, feedback: Feedback) -> Command | None:
        """The motion controller until STOP: FB-EPS towards 0.1 rad, 100 N m per wheel."""
        return Command(0.1, 20.0 * (0.1 - feedback.delta), 100.0, 100.0) if t <= STOP else None

    run = drive_over_can(vehicle, guard, VehicleEcu(timeout=guard.timeout), 5.0, 2.0, controller, seed=3)
    car_rx = Counter(frame.arbitration_id for frame in run.to_car)
    return {"truth": run.truth, "inputs": run.inputs, "records": run.records, "car_rx": car_rx,
            "car_tx": run.car_tx, "bridge": run.bridge, "ecu": run.ecu, "guard": guard}


def test_frames_leave_at_the_dbc_cycle_times(run: dict) -> None:
    seconds = 2.0
    for message in default_database().messages:
        sent = run["car_tx"][message.frame_id] + run["car_rx"][message.frame_id]
        expected = seconds * 1000.0 / message.cycle_time
        assert abs(sent - expected) <= 1.0 + 0.01 * expected, (message.name, sent, expected)
    assert run["bridge"].codec.stats.dropped == 0 and run["ecu"].codec.stats.dropped == 0
    assert run["bridge"].codec.stats.lost == 0 and run["ecu"].unsendable == 0


def test_sensor_frames_carry_the_plant_state(run: dict) -> None:
    truth, noise = run["truth"], SensorParams()
    wheels = [r for r in run["records"] if isinstance(r, WheelSpeedSample)]
    assert len(wheels) >= 199
    errors = np.array([[r.omega_rl - truth[r.t][OMEGA_RL], r.omega_rr - truth[r.t][OMEGA_RR]] for r in wheels])
    assert np.all(np.abs(errors) < 5 * noise.wheel_std + 0.005)  # noise + half a step of 0.01 rad/s
    assert abs(errors.mean()) < 0.02
    at_stop = next(r for r in wheels if r.t >= STOP)
    assert at_stop.omega_rl > wheels[0].omega_rl + 1.0  # 100 N m per wheel for 1.2 s
    gps = [r for r in run["records"] if isinstance(r, GpsSample)]
    assert len(gps) == 2  # fixes taken at 0 s and 1 s, delivered 0.2 s later
    for fix in gps:
        t_fix = round(fix.t_measured, 2)
        assert fix.t - fix.t_measured == pytest.approx(SensorParams().gps_lag_s, abs=1e-3)
        assert abs(fix.x - truth[t_fix][X]) < 5 * noise.gps_pos_std
        assert abs(fix.y - truth[t_fix][Y]) < 5 * noise.gps_pos_std
    assert sum(isinstance(r, ImuSample) for r in run["records"]) >= 199


def test_steering_follows_through_the_bus_within_the_rate_limit(run: dict) -> None:
    times = sorted(run["truth"])
    delta = np.array([run["truth"][t][DELTA] for t in times])
    rates = np.diff(delta) / DT
    assert np.max(np.abs(rates)) <= run["guard"].steer_rate_limit + 1e-9
    reached = next(t for t, d in zip(times, delta) if d > 0.095)
    assert reached < 0.2  # 0.1 rad at ≤ 2 rad/s plus two frame hops and the 10 ms EPS lag
    assert all(abs(run["truth"][t][DELTA] - 0.1) < 0.005 for t in times if 0.4 <= t <= STOP)


def lockstep(vehicle: VehicleParams, guard: GuardParams, v0: float, loss: float, duration: float,
             steering: Callable[[float], float]) -> dict:
    """The car at v0 under a speed-holding, steering controller through the bridge; silence from ``loss`` on."""

    def controller(t: float, feedback: Feedback) -> Command | None:
        """The motion controller: FB-EPS towards the steering profile, a P law holding v0."""
        if t >= loss:
            return None
        torque = float(np.clip(150.0 * (v0 / vehicle.r - feedback.omega), -vehicle.T_max, vehicle.T_max))
        return Command(steering(t), 20.0 * (steering(t) - feedback.delta), torque, torque)

    run = drive_over_can(vehicle, guard, VehicleEcu(), v0, duration, controller, seed=7)
    return {"truth": run.truth, "inputs": run.inputs, "states": run.states}


def lane_change(t: float) -> float:
    """A double lane change's steering: one period of 0.2 rad amplitude, 2 s long, from 0.5 s."""
    return 0.2 * math.sin(math.pi * (t - 0.5)) if 0.5 <= t <= 2.5 else 0.0


@pytest.mark.parametrize("mu", [0.3, 0.5, 1.0])
@pytest.mark.parametrize("loss", [0.9, 1.3, 1.8, 2.3])
def test_lost_commands_at_7_m_s_end_stopped_straight_and_yaw_stable_within_the_braking_distance(loss: float,
                                                                                                 mu: float) -> None:
    vehicle = VehicleParams(mu=mu)
    guard = GuardParams.from_vehicle(vehicle)
    v0 = 7.0
    run = lockstep(vehicle, guard, v0, loss, loss + 10.0, lane_change)
    truth, inputs, states = run["truth"], run["inputs"], run["states"]
    times = sorted(truth)
    lost = truth[loss]
    # the maneuver starts within the timeout + one command cycle
    started = min(t for t in times if states[t] == GuardState.MINIMUM_RISK)
    assert loss < started <= loss + guard.timeout + DT + 1e-9
    # stopped: speed, wheels and torque at zero, steering straight
    end = truth[times[-1]]
    assert abs(end[VX]) < 0.05 and abs(end[VY]) < 0.01 and abs(end[OMEGA_RL]) < 0.2 and abs(end[OMEGA_RR]) < 0.2
    assert states[times[-1]] == GuardState.STOPPED and list(inputs[times[-1]]) == [0.0, 0.0, 0.0]
    assert all(abs(truth[t][DELTA]) < 0.005 for t in times if t >= started + 0.5)  # 0.2 rad at 1 rad/s plus the loop
    # within the braking distance: v0 until the torque has turned from driving to T_brake, then the deceleration
    # of T_brake on both rear wheels (car and wheel inertia), plus 0.5 m for the slow end under k_ω
    t_turn = guard.timeout + 2 * DT + (guard.torque_max + guard.brake_torque) / guard.torque_rate_limit
    decel = 2 * guard.brake_torque / (vehicle.m * vehicle.r + 2 * vehicle.J_wr / vehicle.r)
    bound = v0 * t_turn + v0**2 / (2 * decel) + 0.5
    travelled = math.hypot(end[X] - lost[X], end[Y] - lost[Y])
    assert travelled <= bound, (travelled, bound)
    # yaw stable: once the steering is straight the yaw rate only decays (braking adds no yaw), the heading settles,
    # the side slip stays small, the car ends with no yaw rate
    straight = min(t for t in times if t >= started + 0.5)
    assert max(abs(truth[t][GAMMA]) for t in times if t >= straight) <= abs(truth[straight][GAMMA]) + 1e-3
    assert abs(truth[straight][GAMMA]) < 0.25 and abs(end[GAMMA]) < 0.01
    assert abs(end[THETA] - lost[THETA]) < 0.4
    assert max(abs(truth[t][VY]) / truth[t][VX] for t in times if t >= loss and truth[t][VX] > 1.0) < 0.15
