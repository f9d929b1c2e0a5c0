"""Bridge ↔ virtual bus ↔ ECU emulator ↔ the real plant and sensors, in one process.

A feedback EPS law (the motion controller's, δ̇_cmd = 20 (δ* − δ_meas)) closes the steering loop
through the bus: commands leave as frames, the EPS angle comes back as frames.
"""
from __future__ import annotations

import os
from collections import Counter

import numpy as np
import pytest

from moose.canbus.bridge import BridgeCore
from moose.canbus.bus import open_bus
from moose.canbus.codec import default_database
from moose.canbus.ecu import VehicleEcu
from moose.canbus.safety import Command, GuardParams
from moose.params import VehicleParams
from moose.sensors import Sensors
from moose.signals import EpsSample, GpsSample, ImuSample, WheelSpeedSample
from moose.vehicle import DELTA, OMEGA_RL, OMEGA_RR, VX, VehiclePlant, X, Y, initial_state
from moose.schema import SensorParams

pytestmark = [pytest.mark.can]

DT = 0.01
STOP = 1.2
"""The motion controller falls silent here."""


@pytest.fixture(scope="module")
def run() -> dict:
    vehicle = VehicleParams()
    guard = GuardParams.from_vehicle(vehicle)
    plant = VehiclePlant(vehicle, dt=1e-3)
    plant.reset(initial_state(vehicle, vx=5.0))
    sensors = Sensors(SensorParams(), vehicle, np.random.default_rng(3))
    bridge, ecu = BridgeCore(guard), VehicleEcu(timeout=guard.timeout)
    channel = f"moose-test-plant-{os.getpid()}"
    bridge_side, car_side = open_bus("virtual", channel), open_bus("virtual", channel)
    truth, inputs, records, car_rx, car_tx = {}, {}, [], Counter(), Counter()
    delta_meas = 0.0
    try:
        for k in range(int(round(2.0 / DT)) + 1):
            t = round(k * DT, 9)
            state = plant.state
            truth[t] = state
            if t <= STOP:  # the motion controller: FB-EPS towards 0.1 rad, 100 N m per wheel
                bridge.on_command(Command(0.1, 20.0 * (0.1 - delta_meas), 100.0, 100.0), t)
            for frame in bridge.tick(t):
                bridge_side.send(frame)
            while (frame := car_side.recv(timeout=0.0)) is not None:
                car_rx[frame.arbitration_id] += 1
                ecu.on_frame(frame, t)
            u = ecu.plant_input(t)
            inputs[t] = u
            for frame in ecu.frames(sensors.sample(t, state, plant.imu_specific_force(state, u)), t):
                car_tx[frame.arbitration_id] += 1
                car_side.send(frame)
            while (frame := bridge_side.recv(timeout=0.0)) is not None:
                record = bridge.on_frame(frame, t)
                if record is not None:
                    records.append(record)
                    if isinstance(record, EpsSample):
                        delta_meas = record.delta
            plant.step(u, 10)
    finally:
        bridge_side.shutdown()
        car_side.shutdown()
    return {"truth": truth, "inputs": inputs, "records": records, "car_rx": car_rx, "car_tx": car_tx,
            "bridge": bridge, "ecu": ecu, "guard": guard}


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
    assert wheels[-1].omega_rl > wheels[0].omega_rl + 1.0  # 100 N m per wheel for 1.2 s
    gps = [r for r in run["records"] if isinstance(r, GpsSample)]
    assert len(gps) == 2  # fixes taken at 0 s and 1 s, delivered 0.2 s later
    for fix in gps:
        t_fix = round(fix.t_measured, 2)
        assert fix.t - fix.t_measured == pytest.approx(SensorParams().gps_lag_s, abs=1e-3)
        assert abs(fix.x - truth[t_fix][X]) < 5 * noise.gps_pos_std and abs(fix.y - truth[t_fix][Y]) < 5 * noise.gps_pos_std
    assert sum(isinstance(r, ImuSample) for r in run["records"]) >= 199


def test_steering_follows_through_the_bus_within_the_rate_limit(run: dict) -> None:
    times = sorted(run["truth"])
    delta = np.array([run["truth"][t][DELTA] for t in times])
    rates = np.diff(delta) / DT
    assert np.max(np.abs(rates)) <= run["guard"].steer_rate_limit + 1e-9
    reached = next(t for t, d in zip(times, delta) if d > 0.095)
    assert reached < 0.2  # 0.1 rad at ≤ 2 rad/s plus two frame hops and the 10 ms EPS lag
    assert all(abs(run["truth"][t][DELTA] - 0.1) < 0.005 for t in times if 0.4 <= t <= STOP)


def test_silence_brings_the_car_to_the_safe_state(run: dict) -> None:
    bridge, guard, inputs, truth = run["bridge"], run["guard"], run["inputs"], run["truth"]
    deadline = STOP + guard.timeout
    assert bridge.guard.timed_out
    torque_zero = STOP + guard.timeout + 100.0 / guard.torque_rate_limit + 2 * DT
    assert all(inputs[t][1] == 0.0 and inputs[t][2] == 0.0 and inputs[t][0] == 0.0 for t in inputs if t >= torque_zero)
    ramp = [inputs[t][1] for t in sorted(inputs) if deadline + DT <= t < deadline + 100.0 / guard.torque_rate_limit - DT]
    assert len(ramp) == 3 and all(0.0 < a < 100.0 for a in ramp) and ramp == sorted(ramp, reverse=True)  # ramping down
    held = [truth[t][DELTA] for t in truth if t >= deadline + 2 * DT]
    assert max(held) - min(held) < 1e-6  # steering held where it was
    vx = [truth[t][VX] for t in sorted(truth) if t >= torque_zero + 0.1]
    assert vx[-1] <= vx[0]  # coasting, no more drive
