"""The car on a virtual CAN bus, in lockstep and one process: controller → bridge → bus → ECU emulator → plant
→ sensors → bus → bridge → controller.  Shared by the tests that drive the real plant through the frames."""
from __future__ import annotations

import dataclasses
import os
from collections import Counter
from typing import Callable, Optional

import can
import numpy as np

from moose.canbus.bridge import BridgeCore
from moose.canbus.bus import open_bus
from moose.canbus.ecu import VehicleEcu
from moose.canbus.safety import Command, CommandGuard, GuardParams, GuardState
from moose.params import VehicleParams
from moose.schema import SensorParams
from moose.sensors import Sensors
from moose.signals import EpsSample, WheelSpeedSample
from moose.vehicle import VehiclePlant, initial_state

DT = 0.01
"""The bridge's and the controller's cycle (s); the plant steps at 1 kHz."""


@dataclasses.dataclass
class Feedback:
    """What the controller last received through the bridge: the EPS angle and the mean rear wheel speed."""

    delta: float
    omega: float


Controller = Callable[[float, Feedback], Optional[Command]]
"""(t, feedback) → the command of this cycle, or None for silence."""


@dataclasses.dataclass
class Run:
    truth: dict[float, np.ndarray]
    """The plant's state at each cycle."""
    inputs: dict[float, np.ndarray]
    """The plant input the ECU emulator applied at each cycle."""
    states: dict[float, GuardState]
    """The bridge guard's state after each cycle's tick."""
    records: list
    """Every sample the bridge decoded from the car's frames."""
    to_car: list[can.Message]
    """Every frame the car side received (the bridge's commands, heartbeat and status)."""
    car_tx: Counter
    """Frames the ECU emulator sent, by identifier."""
    bridge: BridgeCore
    ecu: VehicleEcu


def drive_over_can(vehicle: VehicleParams, guard: GuardParams, ecu: VehicleEcu, v0: float, seconds: float,
                   controller: Controller, seed: int) -> Run:
    """``seconds`` of the car from straight running at ``v0``, commanded by ``controller`` through the bridge."""
    plant = VehiclePlant(vehicle, dt=1e-3)
    plant.reset(initial_state(vehicle, vx=v0))
    sensors = Sensors(SensorParams(), vehicle, np.random.default_rng(seed))
    bridge = BridgeCore(guard)
    channel = f"moose-test-lockstep-{os.getpid()}-{id(bridge)}"
    bridge_side, car_side = open_bus("virtual", channel), open_bus("virtual", channel)
    run = Run({}, {}, {}, [], [], Counter(), bridge, ecu)
    feedback = Feedback(0.0, v0 / vehicle.r)
    try:
        for k in range(int(round(seconds / DT)) + 1):
            t = round(k * DT, 9)
            state = plant.state
            run.truth[t] = state
            command = controller(t, feedback)
            if command is not None:
                bridge.on_command(command, t)
            for frame in bridge.tick(t):
                bridge_side.send(frame)
            run.states[t] = bridge.guard.state
            while (frame := car_side.recv(timeout=0.0)) is not None:
                run.to_car.append(frame)
                ecu.on_frame(frame, t)
            u = ecu.plant_input(t)
            run.inputs[t] = u
            for frame in ecu.frames(sensors.sample(t, state, plant.imu_specific_force(state, u)), t):
                run.car_tx[frame.arbitration_id] += 1
                car_side.send(frame)
            while (frame := bridge_side.recv(timeout=0.0)) is not None:
                record = bridge.on_frame(frame, t)
                if record is None:
                    continue
                run.records.append(record)
                if isinstance(record, EpsSample):
                    feedback.delta = record.delta
                elif isinstance(record, WheelSpeedSample):
                    feedback.omega = 0.5 * (record.omega_rl + record.omega_rr)
            plant.step(u, 10)
    finally:
        bridge_side.shutdown()
        car_side.shutdown()
    return run


def commanding(guard: CommandGuard, command: Command, cycles: int, t0: float = 0.0) -> float:
    """``cycles`` guard cycles of ``DT`` from ``t0``, each receiving ``command``; returns the next cycle's time."""
    t = t0
    for _ in range(cycles):
        guard.receive(command)
        guard.output(t)
        t = round(t + DT, 9)
    return t
