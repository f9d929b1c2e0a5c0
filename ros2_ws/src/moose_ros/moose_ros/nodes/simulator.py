"""``vehicle_simulator``: plant, sensors and the scenario's obstacle; owns simulated time (/clock)."""
from __future__ import annotations

import math
import time
from typing import Any, Callable, Optional

import numpy as np

from moose.canbus.safety import CommandGuard, GuardParams, GuardState
from moose.minimum_risk import ActuatorLimits, Command, MinimumRiskManeuver
from moose.sensors import Sensors
from moose.signals import ActuatorCommand, EpsSample, Sample, WheelSpeedSample
from moose.state import VX, X, Y
from moose.timing import CommandHold, DelayLine
from moose.vehicle import VehiclePlant, initial_state

from .. import convert as cv
from ..faults import Fault
from ..graph import ACTUATOR_COMMAND, CLOCK, DIAGNOSTICS, OBSTACLES, ODOM, TF
from ..lockstep import BUS, BUS_POLL, MATCH_RETRY, ROOT, sensor_transit, tick_of
from ..runtime.base import NodeBase
from .base import ERROR, WARN, GraphNode, sensor_publishers


class TopicVehicleIo:
    """The simulator's sensors and actuators as ROS topics.

    The commands reach the plant through the CAN bridge's command guard
    (:class:`moose.canbus.safety.CommandGuard`: the vehicle's limits, the command timeout and the
    minimum-risk maneuver), which here stands in for the bridge and the ECUs behind it: a dead or stalled
    motion controller ends in the same maneuver as in the ``can`` graph, from the EPS angle and wheel
    speeds the simulator measures.
    """

    def __init__(self, node: "VehicleSimulator") -> None:
        self.node = node
        self.guard = CommandGuard(GuardParams.from_vehicle(node.config.vehicle, timeout=node.params.command_timeout,
                                                           maneuver=node.config.minimum_risk), period=node.dt)
        self.pub = sensor_publishers(node, 0.0)  # simulated time starts at 0
        # the command path's delay (moose.timing): a command computed at t reaches the guard at t + d_c
        self.hold: CommandHold[Command] = CommandHold(node.config.timing.command_delay_s, node.dt)
        node.subscribe(ACTUATOR_COMMAND, self.on_command)

    def on_command(self, c: ActuatorCommand) -> None:
        """A command, computed at the simulator's current tick (in lockstep: the tick it was made for)."""
        self.hold.push(self.node.t, Command(c.steering_angle, c.steering_rate, c.torque_rl, c.torque_rr))

    def send(self, sample: Sample, t: float) -> None:
        if isinstance(sample, EpsSample):
            self.guard.observe_angle(sample.delta)
        elif isinstance(sample, WheelSpeedSample):
            self.guard.observe_wheel_speeds(sample.omega_rl, sample.omega_rr)
        publish, convert = self.pub[type(sample)]
        publish(convert(self.node.rt, sample))

    def close(self) -> None:
        """Nothing to release: topics go with the node."""

    def poll(self) -> None:
        """The commands arrive as messages (the node's subscription)."""

    def command(self, t: float) -> np.ndarray:
        for command in self.hold.arrivals(t):
            self.guard.receive(command)
        out = self.guard.output(t)
        if self.guard.state in (GuardState.MINIMUM_RISK, GuardState.STOPPED):
            done = "stopped by" if self.guard.state == GuardState.STOPPED else "running"
            self.node.problem("commands_lost", WARN, f"actuator commands lost: {done} the minimum-risk maneuver")
        else:
            self.node.problem("commands_lost", None)
        return np.array([out.steering_rate, out.torque_rl, out.torque_rr])


class CanVehicleIo:
    """The vehicle-side ECUs: sensors as frames of config/kanon.dbc, commands from the bus (ECU emulator).

    In real time the bus is the hop between the car and the stack: the frames take the time they take.  In
    lockstep (:mod:`moose_ros.lockstep`) the bridge decodes the sensor frames of tick k at k and the stack reads them
    one tick later (the bus hop of the sensor path: the simulator delays the samples by d_s minus that tick), and the
    bridge sends the command frames of tick k at k, which reach the ECUs through the command delay
    (:class:`moose.timing.CommandHold`, the frames of one tick together)."""

    def __init__(self, node: "VehicleSimulator") -> None:
        from moose.canbus.ecu import VehicleEcu

        self.node = node
        self.bus = node.params.open_bus(node.name)
        maneuver = (MinimumRiskManeuver(node.config.minimum_risk, ActuatorLimits.from_vehicle(node.config.vehicle),
                                        node.dt) if node.params.ecu_minimum_risk else None)
        self.ecu = VehicleEcu(timeout=node.params.command_timeout, maneuver=maneuver)
        delay = node.config.timing.command_delay_s if node.lockstep else 0.0
        self.hold: CommandHold[tuple[Any, ...]] = CommandHold(delay, node.dt)
        self.inbox: list[Any] = []
        """The command frames of the current tick."""
        if node.join is not None:
            node.join.add(BUS)

    def send(self, sample: Sample, t: float) -> None:
        for frame in self.ecu.encode(sample, t):
            self.bus.send(frame)
            self.node.announce(BUS)

    def poll(self) -> None:
        """Lockstep: the frames on the bus go to the tick join (handed over with the bridge's tick)."""
        assert self.node.join is not None
        while (frame := self.bus.recv(timeout=0.0)) is not None:
            if not self.ecu.codec.own(frame):  # the multicast bus echoes our own frames
                self.node.join.message(BUS, lambda frame=frame: self.inbox.append(frame))

    def close(self) -> None:
        self.bus.shutdown()

    def command(self, t: float) -> np.ndarray:
        if not self.node.lockstep:
            while (frame := self.bus.recv(timeout=0.0)) is not None:
                self.inbox.append(frame)
        if self.inbox:
            self.hold.push(t, tuple(self.inbox))
            self.inbox.clear()
        for frames in self.hold.arrivals(t):
            for frame in frames:
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

    def __init__(self, rt: NodeBase) -> None:
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
        self.pub: dict[str, Callable[[Any], None]] = {
            "clock": CLOCK.publisher(rt), "odom": self.publisher(ODOM), "tf": TF.publisher(rt),
            "obstacles": self.publisher(OBSTACLES)}
        self.stepped = False
        """The plant has taken a step (its specific force is the IMU's)."""
        # the sensor path's delay (moose.timing): a sample handed over at t reaches the observer at t + d_s; on the
        # CAN bus the bus is the hop (in real time all of it, in lockstep one tick: CanVehicleIo)
        self.in_transit: DelayLine = DelayLine(sensor_transit(self.config, self.params.vehicle_bus,
                                                              bool(self.params.lockstep_nodes)), self.dt)
        self.nodes = tuple(self.params.lockstep_nodes)
        self.faults = [Fault.parse(text) for text in self.params.faults]
        self.progress: Optional[float] = None
        """Lockstep: wall-clock time of the last tick (``None`` before simulated time starts)."""
        self.connecting: Optional[float] = None
        """Lockstep: since when every node has announced itself but the graph is not yet connected."""
        self.io = CanVehicleIo(self) if self.params.vehicle_bus == "can" else TopicVehicleIo(self)
        # simulated time starts once every node named in ``wait_for`` has reported (startup of the graph)
        self.waiting = set(self.params.wait_for)
        self.startup_deadline = self.params.startup_timeout
        self.wall_start: Optional[float] = None
        self.subscribe(DIAGNOSTICS, self.on_diagnostics)
        if self.lockstep:  # the graph paces simulated time (moose_ros.lockstep)
            rt.timer(BUS_POLL if self.params.vehicle_bus == "can" else MATCH_RETRY, self.lockstep_timer)
        else:  # wall-clock pacing: one motion step every dt / rate seconds; simulated time is published on /clock
            rt.timer(self.dt / self.params.rate / 2.0, self.step)
        self.half = False
        """Real time: the tick's samples are out, its commands are awaited until the half tick."""

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

    def expected(self, t: float) -> tuple[str, ...]:
        """Lockstep: the nodes the graph waits for at ``t`` (the fault plan: a faulted node drops out at its fault's
        time for the rest of the run)."""
        return tuple(n for n in self.nodes if not any(f.node == n and t >= f.at - 1e-9 for f in self.faults))

    def started(self) -> bool:
        """Whether simulated time runs: every node named in ``wait_for`` has reported (or the start-up timeout
        passed), and in lockstep every publisher reaches its readers."""
        if self.waiting:
            self.wall_start = self.wall_start or time.monotonic()
            if time.monotonic() - self.wall_start < self.startup_deadline:
                return False
            self.rt.log_warn(f"starting without {sorted(self.waiting)}: not up after {self.startup_deadline} s")
            self.waiting.clear()
        return self.lockstep is False or self.matched()

    def step(self) -> None:
        """Real time, two timer periods per motion tick (``rate``): the tick's samples at its start, the plant's
        step at its half with the commands that arrived by then.  A command computed from the tick's samples within
        half a tick acts through the command delay as in the lockstep loop; a later one a tick later (a
        scheduling delay the timing model does not have, measured by bench/bench_realtime.py)."""
        if self.finished or not self.started():
            return
        if self.half:
            self.advance()
        else:
            self.publish_tick()
        self.half = not self.half

    def tick(self) -> None:
        """One whole motion tick at once: the samples out, the commands received so far in, the plant's step."""
        if not self.finished:
            self.publish_tick()
            self.advance()

    def lockstep_timer(self) -> None:
        """Lockstep: start simulated time when the graph is up, and end a run whose graph stopped reporting."""
        if self.finished:
            return
        now = time.monotonic()
        if self.progress is None:
            if self.started():
                self.progress = now
                self.publish_tick()
            elif not self.waiting:  # every node announced itself, but not every reader is connected
                self.connecting = self.connecting or now
                if now - self.connecting > self.params.lockstep_timeout:
                    self.stuck(now - self.connecting, "the graph did not connect (a publisher without its readers)")
            return
        self._pump()  # the bus's frames, read here (no message wakes the node for them)
        if self.finished:
            return
        if now - self.progress > self.params.lockstep_timeout:
            assert self.join is not None
            k = self.join.next
            missing = [n for n, lag in self.join.waits.items() if n in self.expected(self.t)
                       and k - lag not in self.join.markers[n]]
            self.stuck(now - self.progress, f"no tick from {', '.join(missing) or 'the graph'}")

    def stuck(self, waited: float, why: str) -> None:
        """Lockstep: the graph stopped reporting; end the run and say so (``lockstep_stuck``)."""
        self.problem("lockstep_stuck", ERROR, f"lockstep stuck at t = {self.t:.2f} s: {why} for {waited:.1f} s "
                                              "(wall clock)")
        self.finish("stuck")

    def _pump(self) -> None:
        """Lockstep: step the plant past tick k once every expected node has reported it (with its commands)."""
        join = self.join
        assert join is not None
        while not self.finished and self.progress is not None:
            self.io.poll()
            step = join.take()
            if step is None:
                return
            for _topic, deliver in step[1]:
                deliver()
            self.advance()
            if self.finished:
                return
            self.progress = time.monotonic()
            self.publish_tick()
            self._publish_on_change()

    def publish_tick(self) -> None:
        """Tick k: the clock, the samples due (after the sensor delay), ground truth, the obstacle when it appears;
        in lockstep the root marker last."""
        rt, t = self.rt, self.t
        clock = rt.make(CLOCK.type)
        clock.clock.sec, clock.clock.nanosec = int(math.floor(t)), int(round((t - math.floor(t)) * 1e9)) % 1_000_000_000
        self.pub["clock"](clock)
        state = self.plant.state
        # the IMU's specific force of the step that led here (at t = 0: the cruise, no command yet), as the loop's
        force = self.plant.specific_force if self.stepped else self.plant.imu_specific_force(state, np.zeros(3))
        for sample in self.sensors.sample(t, state, force):
            self.in_transit.push(t, sample)
        for sample in self.in_transit.pop_due(t):
            self.io.send(sample, t)
        self.pub["odom"](cv.odometry_to_msg(rt, t, state))
        self.pub["tf"](cv.truth_tf(rt, t, state))
        if not self.appeared and self.scenario.appears(float(state[X]), float(state[VX])):
            self.appeared = True
            self.pub["obstacles"](cv.obstacles_to_msg(rt, t, [self.scenario.danger_zone]))
        self.values = {"t": f"{t:.2f}", "x": f"{state[X]:.2f}", "y": f"{state[Y]:.2f}"}
        if self.join is not None:
            expected = self.expected(t)
            k = tick_of(t, self.dt)
            self.join.marker(ROOT, k, (), expected)
            self.publish_marker(k, expected)

    def advance(self) -> None:
        """The command acting at the current tick drives the plant to the next one; the run ends at its end."""
        t = self.t
        u = self.io.command(t)
        if t >= self.end - 1e-9:
            self.finish("finished")
            return
        self.plant.step(u, self.steps)
        self.stepped = True
        self.t = round(t + self.dt, 9)

    def finish(self, message: str) -> None:
        self.finished = True
        self.message = message
        self.publish_diagnostics()
        self.io.close()
        self.rt.shutdown()
