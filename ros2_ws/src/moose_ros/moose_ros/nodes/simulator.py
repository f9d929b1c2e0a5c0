"""``vehicle_simulator``: plant, sensors and the scenario's obstacle; owns simulated time (/clock)."""
from __future__ import annotations

import math
import time
from typing import Any, Optional

import numpy as np

from moose.canbus.safety import CommandGuard, GuardParams, GuardState
from moose.minimum_risk import ActuatorLimits, Command, MinimumRiskManeuver
from moose.sensors import Sensors
from moose.signals import ActuatorCommand, EpsSample, WheelSpeedSample
from moose.state import VX, X, Y
from moose.vehicle import VehiclePlant, initial_state

from .. import convert as cv
from ..graph import ACTUATOR_COMMAND, CLOCK, DIAGNOSTICS, OBSTACLES, ODOM, TF
from .base import WARN, GraphNode, sensor_publishers


class TopicVehicleIo:
    """The simulator's sensors and actuators as ROS topics.

    The commands reach the plant through the CAN bridge's command guard
    (:class:`moose.canbus.safety.CommandGuard`: the vehicle's limits, the command timeout and the
    minimum-risk maneuver), which here stands in for the bridge and the ECUs behind it: a dead or stalled
    motion controller ends in the same maneuver as in the ``can`` graph, from the EPS angle and wheel
    speeds the simulator measures.
    """

    def __init__(self, node: "VehicleSimulator") -> None:
        rt = node.rt
        self.node = node
        self.guard = CommandGuard(GuardParams.from_vehicle(node.config.vehicle, timeout=node.params.command_timeout,
                                                           maneuver=node.config.minimum_risk), period=node.dt)
        self.pub = sensor_publishers(rt, 0.0)  # simulated time starts at 0
        node.subscribe(ACTUATOR_COMMAND, self.on_command)

    def on_command(self, c: ActuatorCommand) -> None:
        self.guard.receive(Command(c.steering_angle, c.steering_rate, c.torque_rl, c.torque_rr))

    def send(self, sample: Any, t: float) -> None:
        if isinstance(sample, EpsSample):
            self.guard.observe_angle(sample.delta)
        elif isinstance(sample, WheelSpeedSample):
            self.guard.observe_wheel_speeds(sample.omega_rl, sample.omega_rr)
        publish, convert = self.pub[type(sample)]
        publish(convert(self.node.rt, sample))

    def close(self) -> None:
        """Nothing to release: topics go with the node."""

    def command(self, t: float) -> np.ndarray:
        out = self.guard.output(t)
        if self.guard.state in (GuardState.MINIMUM_RISK, GuardState.STOPPED):
            done = "stopped by" if self.guard.state == GuardState.STOPPED else "running"
            self.node.problem("commands_lost", WARN, f"actuator commands lost: {done} the minimum-risk maneuver")
        else:
            self.node.problem("commands_lost", None)
        return np.array([out.steering_rate, out.torque_rl, out.torque_rr])


class CanVehicleIo:
    """The vehicle-side ECUs: sensors as frames of config/kanon.dbc, commands from the bus (ECU emulator)."""

    def __init__(self, node: "VehicleSimulator") -> None:
        from moose.canbus.ecu import VehicleEcu

        self.node = node
        self.bus = node.params.open_bus(node.name)
        maneuver = (MinimumRiskManeuver(node.config.minimum_risk, ActuatorLimits.from_vehicle(node.config.vehicle),
                                        node.dt) if node.params.ecu_minimum_risk else None)
        self.ecu = VehicleEcu(timeout=node.params.command_timeout, maneuver=maneuver)

    def send(self, sample: Any, t: float) -> None:
        for frame in self.ecu.encode(sample, t):
            self.bus.send(frame)

    def close(self) -> None:
        self.bus.shutdown()

    def command(self, t: float) -> np.ndarray:
        while (frame := self.bus.recv(timeout=0.0)) is not None:
            self.ecu.on_frame(frame, t)
        u = self.ecu.plant_input(t)
        if self.ecu.commands_lost:  # no bridge on the bus: the car is the ECUs' own, not the stack's
            what = ("the ECUs' own minimum-risk maneuver" if self.ecu.minimum_risk
                    else "zero torque, EPS stopped (steering held)")
            self.node.problem("ecu_timeout", WARN, f"vehicle ECUs' command timeout: {what}; the stack no longer "
                                                   "controls the car")
        else:
            self.node.problem("ecu_timeout", None)
        return u


class VehicleSimulator(GraphNode):
    """Plant, sensors and the scenario's obstacle; owns simulated time (/clock).

    ``vehicle_bus`` chooses how sensors and actuators are reached: ``topics`` (the
    simulator publishes the sensor topics itself) or ``can`` (it is the vehicle-side ECU
    emulator behind config/kanon.dbc, and the ``can_bridge`` node makes the topics).
    """

    name = "vehicle_simulator"

    def __init__(self, rt: Any) -> None:
        super().__init__(rt)
        self.scenario = self.params.load_scenario()
        vehicle = self.config.vehicle  # the road's μ: the scenario's (GraphNode)
        self.plant = VehiclePlant(vehicle, dt=self.config.simulation.plant_dt)
        self.plant.reset(initial_state(vehicle, x=self.scenario.start_x, vx=self.scenario.v_init))
        self.sensors = Sensors(self.config.sensors, vehicle, np.random.default_rng(self.params.seed))
        self.dt = 1.0 / self.config.simulation.motion_rate_hz
        self.steps = self.config.simulation.plant_steps_per_motion
        self.end = self.scenario.lead_time + self.scenario.duration
        self.t = 0.0
        self.appeared = False
        self.finished = False
        self.pub = {"clock": CLOCK.publisher(rt), "odom": ODOM.publisher(rt), "tf": TF.publisher(rt),
                    "obstacles": OBSTACLES.publisher(rt)}
        self.io = CanVehicleIo(self) if self.params.vehicle_bus == "can" else TopicVehicleIo(self)
        # simulated time starts once every node named in ``wait_for`` has reported (startup of the graph)
        self.waiting = set(self.params.wait_for)
        self.startup_deadline = self.params.startup_timeout
        self.wall_start: Optional[float] = None
        self.subscribe(DIAGNOSTICS, self.on_diagnostics)
        # wall-clock pacing: one motion step every dt / rate seconds; simulated time is published on /clock
        rt.timer(self.dt / self.params.rate, self.step)

    def stamp_time(self) -> float:
        """Simulated time, as every other message of the simulator: it is the graph's clock, not on
        ``use_sim_time`` itself, and a wall-clock stamp would be refused as far ahead by every node on
        simulated time (the motion controller then took the simulator for silent and stopped the car)."""
        return self.t

    def on_inputs(self, stale: dict[str, Optional[float]], now: float) -> None:
        """The commands are the guard's to supervise (:class:`TopicVehicleIo`); the ECU emulator times them out
        itself (:class:`moose.canbus.ecu.VehicleEcu`)."""

    def on_diagnostics(self, statuses: list[tuple[str, int, str]]) -> None:
        for name, _level, _message in statuses:
            self.waiting.discard(name)

    def step(self) -> None:
        if self.finished:
            return
        if self.waiting:
            self.wall_start = self.wall_start or time.monotonic()
            if time.monotonic() - self.wall_start < self.startup_deadline:
                return
            self.rt.log_warn(f"starting without {sorted(self.waiting)}: not up after {self.startup_deadline} s")
            self.waiting.clear()
        rt, t = self.rt, self.t
        clock = rt.make(CLOCK.type)
        clock.clock.sec, clock.clock.nanosec = int(math.floor(t)), int(round((t - math.floor(t)) * 1e9)) % 1_000_000_000
        self.pub["clock"](clock)
        state = self.plant.state
        u = self.io.command(t)
        for sample in self.sensors.sample(t, state, self.plant.imu_specific_force(state, u)):
            self.io.send(sample, t)
        self.pub["odom"](cv.odometry_to_msg(rt, t, state))
        self.pub["tf"](cv.truth_tf(rt, t, state))
        if not self.appeared and self.scenario.appears(float(state[X]), float(state[VX])):
            self.appeared = True
            self.pub["obstacles"](cv.obstacles_to_msg(rt, t, [self.scenario.danger_zone]))
        self.values = {"t": f"{t:.2f}", "x": f"{state[X]:.2f}", "y": f"{state[Y]:.2f}"}
        if t >= self.end - 1e-9:
            self.finished = True
            self.message = "finished"
            self.publish_diagnostics()
            self.io.close()
            rt.shutdown()
            return
        self.plant.step(u, self.steps)
        self.t = round(t + self.dt, 9)
