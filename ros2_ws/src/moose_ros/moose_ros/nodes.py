"""The node graph (paper Fig. 3): one node per ECU function, thin shells around the core's blocks.

Run one with ``moose node NAME [--params FILE] [--param key=value ...]`` or, on ROS 2,
``ros2 run moose_ros NAME``.  Topics, rates and QoS: docs/design.md, "Node graph".
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from typing import Any, Callable, Optional, Sequence

import numpy as np
import yaml

from moose.config import config_from_mapping
from moose.detector import ObstacleDetector
from moose.maneuver import MaxSteeringTable
from moose.motion import MotionController
from moose.mpc import MpcPlanner
from moose.msf import MsfPlanner
from moose.observer import StateObserver
from moose.params import ParamError
from moose.scenario import adhoc_scenario, load_scenario
from moose.sensors import Sensors
from moose.signals import Blend, EpsSample, GpsSample, ImuSample, PlannerInput, Reference, StateEstimate, WheelSpeedSample
from moose.schema import Config
from moose.vehicle import VehiclePlant, initial_state
from moose.planning import PlanningStep, new_obstacle
from moose.weight import WeightFunction

from . import convert as cv
from .runtime import QOS_CLOCK, QOS_DEFAULT, QOS_LATCHED, QOS_LATCHED_READER, QOS_SENSOR, create_node

OK, WARN, ERROR = 0, 1, 2


class GraphNode:
    """Runtime node, the configuration, and a 1 Hz diagnostics heartbeat."""

    name = "node"

    def __init__(self, rt: Any) -> None:
        self.rt = rt
        known = {f.name for f in dataclasses.fields(Config)}
        self.config = config_from_mapping({k: v for k, v in rt.parameters.items() if k in known}, where=f"{self.name} parameters")
        if rt.param("scenario") is not None or rt.param("speed") is not None:
            self.config = scenario_from_params(rt).configure(self.config)  # the simulated road's μ
        # transient local: a late joiner (the simulator waiting for the graph) sees each node's last status
        self._diag = rt.publisher("diagnostic_msgs/msg/DiagnosticArray", "/diagnostics", QOS_LATCHED)
        self.level, self.message, self.values = OK, "running", {}
        rt.timer(1.0, self.publish_diagnostics)

    def publish_diagnostics(self) -> None:
        self._diag(cv.diagnostic_to_msg(self.rt, self.rt.now(), self.name, self.level, self.message, self.values))

    def table(self) -> MaxSteeringTable:
        return MaxSteeringTable.build(self.config.model_vehicle, self.config.maneuver)


def sensor_publishers(rt: Any) -> dict[type, tuple[Callable[[Any], None], Callable[[Any, Any], Any]]]:
    """Publisher and converter of each sensor sample type: the vehicle's sensor topics."""
    return {
        ImuSample: (rt.publisher("sensor_msgs/msg/Imu", "/vehicle/imu", QOS_SENSOR), cv.imu_to_msg),
        GpsSample: (rt.publisher("nav_msgs/msg/Odometry", "/vehicle/gps", QOS_DEFAULT), cv.gps_to_msg),
        WheelSpeedSample: (rt.publisher("moose_msgs/msg/WheelSpeeds", "/vehicle/wheel_speeds", QOS_SENSOR), cv.wheels_to_msg),
        EpsSample: (rt.publisher("moose_msgs/msg/SteeringReport", "/vehicle/steering", QOS_SENSOR), cv.steering_to_msg),
    }


class TopicVehicleIo:
    """The simulator's sensors and actuators as ROS topics."""

    def __init__(self, node: "VehicleSimulator") -> None:
        rt = node.rt
        self.node = node
        self.timeout = float(rt.param("command_timeout", 0.1))
        self.u = np.zeros(3)
        self.last_command = -math.inf
        self.pub = sensor_publishers(rt)
        rt.subscription("moose_msgs/msg/ActuatorCommand", "/control/actuator_command", self.on_command, QOS_DEFAULT)

    def on_command(self, msg: Any) -> None:
        u = np.array([msg.steering_rate, msg.torque_rl, msg.torque_rr], dtype=float)
        self.u = u if np.all(np.isfinite(u)) else np.zeros(3)
        self.last_command = self.node.t

    def send(self, sample: Any, t: float) -> None:
        publish, convert = self.pub[type(sample)]
        publish(convert(self.node.rt, sample))

    def close(self) -> None:
        """Nothing to release: topics go with the node."""

    def command(self, t: float) -> np.ndarray:
        if t - self.last_command <= self.timeout:
            return self.u
        if t > 1.0:
            self.node.level, self.node.message = WARN, "actuator command timeout: zero torque, steering held"
        return np.zeros(3)


class CanVehicleIo:
    """The vehicle-side ECUs: sensors as frames of config/kanon.dbc, commands from the bus (ECU emulator)."""

    def __init__(self, node: "VehicleSimulator") -> None:
        from moose.canbus.bus import open_bus
        from moose.canbus.ecu import VehicleEcu

        rt = node.rt
        self.bus = open_bus(str(rt.param("can_interface", "udp_multicast")), str(rt.param("can_channel", "239.74.163.2")),
                            port=rt.param("can_port"))
        self.ecu = VehicleEcu(timeout=float(rt.param("command_timeout", 0.05)))

    def send(self, sample: Any, t: float) -> None:
        for frame in self.ecu.encode(sample, t):
            self.bus.send(frame)

    def close(self) -> None:
        self.bus.shutdown()

    def command(self, t: float) -> np.ndarray:
        while (frame := self.bus.recv(timeout=0.0)) is not None:
            self.ecu.on_frame(frame, t)
        return self.ecu.plant_input(t)


class VehicleSimulator(GraphNode):
    """Plant, sensors and the scenario's obstacle; owns simulated time (/clock).

    ``vehicle_bus`` chooses how sensors and actuators are reached: ``topics`` (the
    simulator publishes the sensor topics itself) or ``can`` (it is the vehicle-side ECU
    emulator behind config/kanon.dbc, and the ``can_bridge`` node makes the topics).
    """

    name = "vehicle_simulator"

    def __init__(self, rt: Any) -> None:
        super().__init__(rt)
        self.scenario = scenario_from_params(rt)
        vehicle = self.config.vehicle
        self.plant = VehiclePlant(vehicle, dt=self.config.simulation.plant_dt)
        self.plant.reset(initial_state(vehicle, x=self.scenario.start_x, vx=self.scenario.v_init))
        self.sensors = Sensors(self.config.sensors, vehicle, np.random.default_rng(int(rt.param("seed", 0))))
        self.dt = 1.0 / self.config.simulation.motion_rate_hz
        self.steps = self.config.simulation.plant_steps_per_motion
        self.end = self.scenario.lead_time + self.scenario.duration
        self.t = 0.0
        self.appeared = False
        self.finished = False
        self.pub = {
            "clock": rt.publisher("rosgraph_msgs/msg/Clock", "/clock", QOS_CLOCK),
            "odom": rt.publisher("nav_msgs/msg/Odometry", "/vehicle/odom", QOS_SENSOR),
            "obstacles": rt.publisher("moose_msgs/msg/ObstacleArray", "/perception/obstacles", QOS_LATCHED),
        }
        bus = str(rt.param("vehicle_bus", "topics"))
        if bus not in ("topics", "can"):
            raise ParamError(f"vehicle_bus = {bus!r} is invalid: expected 'topics' or 'can'")
        self.io = CanVehicleIo(self) if bus == "can" else TopicVehicleIo(self)
        # simulated time starts once every node named in ``wait_for`` has reported (startup of the graph)
        self.waiting = set(rt.param("wait_for", []) or [])
        self.startup_deadline = float(rt.param("startup_timeout", 60.0))
        self.wall_start: Optional[float] = None
        rt.subscription("diagnostic_msgs/msg/DiagnosticArray", "/diagnostics", self.on_diagnostics, QOS_LATCHED_READER)
        # wall-clock pacing: one motion step every dt / rate seconds; simulated time is published on /clock
        rt.timer(self.dt / float(rt.param("rate", 1.0)), self.step)

    def on_diagnostics(self, msg: Any) -> None:
        for status in msg.status:
            self.waiting.discard(status.name)

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
        clock = rt.make("rosgraph_msgs/msg/Clock")
        clock.clock.sec, clock.clock.nanosec = int(math.floor(t)), int(round((t - math.floor(t)) * 1e9)) % 1_000_000_000
        self.pub["clock"](clock)
        state = self.plant.state
        u = self.io.command(t)
        for sample in self.sensors.sample(t, state, self.plant.imu_specific_force(state, u)):
            self.io.send(sample, t)
        self.pub["odom"](cv.odometry_to_msg(rt, t, state))
        if not self.appeared and self.scenario.appears(float(state[0]), float(state[3])):
            self.appeared = True
            self.pub["obstacles"](cv.obstacles_to_msg(rt, t, [self.scenario.danger_zone]))
        self.values = {"t": f"{t:.2f}", "x": f"{state[0]:.2f}", "y": f"{state[1]:.2f}"}
        if t >= self.end - 1e-9:
            self.finished = True
            self.message = "finished"
            self.publish_diagnostics()
            self.io.close()
            rt.shutdown()
            return
        self.plant.step(u, self.steps)
        self.t = round(t + self.dt, 9)


class Observer(GraphNode):
    """State observer: IMU, GPS, wheel speeds, EPS → /perception/state at the IMU rate."""

    name = "observer"

    def __init__(self, rt: Any) -> None:
        super().__init__(rt)
        scenario = scenario_from_params(rt)
        start = initial_state(self.config.vehicle, x=scenario.start_x, vx=scenario.v_init)
        self.observer = StateObserver(self.config.observer, self.config.model_vehicle,
                                      StateEstimate(0.0, start[0], 0.0, 0.0, scenario.v_init, 0.0, 0.0, 0.0))
        self.pub = rt.publisher("moose_msgs/msg/StateEstimate", "/perception/state", QOS_DEFAULT)
        self.dropped = 0
        rt.subscription("sensor_msgs/msg/Imu", "/vehicle/imu", lambda m: self.feed(cv.imu_from_msg(m), True), QOS_SENSOR)
        rt.subscription("nav_msgs/msg/Odometry", "/vehicle/gps", lambda m: self.feed(cv.gps_from_msg(m, self.rt.now())), QOS_DEFAULT)
        rt.subscription("moose_msgs/msg/WheelSpeeds", "/vehicle/wheel_speeds", lambda m: self.feed(cv.wheels_from_msg(m)), QOS_SENSOR)
        rt.subscription("moose_msgs/msg/SteeringReport", "/vehicle/steering", lambda m: self.feed(cv.steering_from_msg(m)), QOS_SENSOR)

    def feed(self, sample: Any, publish: bool = False) -> None:
        try:
            self.observer.update(sample)
        except ValueError:
            self.dropped += 1  # out of order (transport reordering): counted, never fatal
            self.level, self.message, self.values = WARN, "out-of-order samples dropped", {"dropped": self.dropped}
            return
        if publish:
            self.pub(cv.estimate_to_msg(self.rt, self.observer.estimate()))


class Detector(GraphNode):
    """Obstacle detector: state + visible danger zones → /perception/threat."""

    name = "obstacle_detector"

    def __init__(self, rt: Any) -> None:
        super().__init__(rt)
        self.detector = ObstacleDetector(self.config.detector, self.table())
        self.obstacles: list = []
        self.pub = rt.publisher("moose_msgs/msg/Threat", "/perception/threat", QOS_DEFAULT)
        rt.subscription("moose_msgs/msg/ObstacleArray", "/perception/obstacles",
                        lambda m: setattr(self, "obstacles", [cv.obstacle_from_msg(o) for o in m.obstacles]), QOS_LATCHED)
        rt.subscription("moose_msgs/msg/StateEstimate", "/perception/state", self.on_state, QOS_DEFAULT)

    def on_state(self, msg: Any) -> None:
        estimate = cv.estimate_from_msg(msg)
        self.pub(cv.threat_to_msg(self.rt, estimate.t, self.detector.update(estimate.t, estimate, self.obstacles)))


class Planner(GraphNode):
    """MPC or MSF planner at 5 Hz, and at once on a new obstacle."""

    def __init__(self, rt: Any, kind: str) -> None:
        self.name = f"{kind}_planner"
        super().__init__(rt)
        self.kind = kind
        cfg = self.config
        self.planner = MpcPlanner(cfg.mpc, cfg.grid) if kind == "mpc" else MsfPlanner(cfg.msf, cfg.grid, self.table())
        self.scenario = scenario_from_params(rt)
        self.seen_threat = False
        self.estimate: Optional[StateEstimate] = None
        self.threat = None
        self.guess: Optional[np.ndarray] = None
        self.pub = rt.publisher("moose_msgs/msg/PlannerOutput", f"/planning/{kind}", QOS_DEFAULT)
        rt.subscription("moose_msgs/msg/StateEstimate", "/perception/state",
                        lambda m: setattr(self, "estimate", cv.estimate_from_msg(m)), QOS_DEFAULT)
        rt.subscription("moose_msgs/msg/Threat", "/perception/threat", self.on_threat, QOS_DEFAULT)
        rt.subscription("moose_msgs/msg/Blend", "/planning/blend",
                        lambda m: setattr(self, "guess", WeightFunction.next_initial_guess(Blend(m.weight_mpc, cv.blend_accel(m)))),
                        QOS_DEFAULT)
        rt.timer(1.0 / cfg.planning_rate_hz, self.plan)

    def on_threat(self, msg: Any) -> None:
        threat = cv.threat_from_msg(msg)
        new = new_obstacle(self.threat, threat)
        self.threat = threat
        self.seen_threat = self.seen_threat or threat is not None
        if new:
            self.plan()

    def plan(self) -> None:
        if self.estimate is None:
            return
        t = self.rt.now()
        inp = PlannerInput(t, self.estimate, self.threat, self.scenario.desired_speed(self.seen_threat), self.guess,
                           y_lane=0.0)
        result = self.planner.plan(inp)
        self.values = {"status": result.status, "solve_ms": f"{result.solve_time_s * 1e3:.2f}"}
        self.level = OK if result.status in ("converged", "capped", "ok", "idle") else WARN
        self.pub(cv.plan_to_msg(self.rt, t, self.kind, result))


class WeightFbl(GraphNode):
    """Weight function and FBL: blends the plans of one planning instant, emits the references."""

    name = "weight_fbl"

    def __init__(self, rt: Any) -> None:
        super().__init__(rt)
        cfg = self.config
        self.step = PlanningStep(cfg, str(rt.param("planner", cfg.simulation.planner)), planners=False)  # type: ignore[arg-type]
        self.mode = self.step.mode
        self.mpc_timeout = float(rt.param("mpc_timeout", 0.1))
        self.estimate: Optional[StateEstimate] = None
        self.threat = None
        self.pending: dict[str, tuple[float, Any]] = {}
        self.last_mpc = -math.inf
        self.pub_blend = rt.publisher("moose_msgs/msg/Blend", "/planning/blend", QOS_DEFAULT)
        self.pub_ref = rt.publisher("moose_msgs/msg/Reference", "/control/reference", QOS_DEFAULT)
        rt.subscription("moose_msgs/msg/StateEstimate", "/perception/state", self.on_state, QOS_DEFAULT)
        rt.subscription("moose_msgs/msg/Threat", "/perception/threat", lambda m: setattr(self, "threat", cv.threat_from_msg(m)), QOS_DEFAULT)
        rt.subscription("moose_msgs/msg/PlannerOutput", "/planning/mpc", lambda m: self.on_plan("mpc", m), QOS_DEFAULT)
        rt.subscription("moose_msgs/msg/PlannerOutput", "/planning/msf", lambda m: self.on_plan("msf", m), QOS_DEFAULT)

    def on_plan(self, kind: str, msg: Any) -> None:
        self.pending[kind] = (cv.time_of(msg), cv.plan_from_msg(msg))
        if kind == "mpc":
            self.last_mpc = self.rt.now()
        self.try_blend()

    def try_blend(self) -> None:
        if self.estimate is None:
            return
        mpc, msf = self.pending.get("mpc"), self.pending.get("msf")
        if self.mode == "mpc" and mpc:
            t, plans = mpc[0], (mpc[1], None)
        elif self.mode == "msf" and msf:
            t, plans = msf[0], (None, msf[1])
        elif self.mode == "combined" and msf and mpc and abs(mpc[0] - msf[0]) < 1e-6:
            t, plans = msf[0], (mpc[1], msf[1])
        elif self.mode == "combined" and msf and self.rt.now() - self.last_mpc > self.mpc_timeout + 0.2:
            # MPC silent: blend without it (weight 0) and say so
            t, plans = msf[0], (None, msf[1])
            self.level, self.message = WARN, "mpc_planner silent: MSF only"
        else:
            return
        record = self.step.combine(t, self.estimate, self.threat, *plans)
        blend = record.blend
        if self.mode != "combined" or not self.message.startswith("mpc_planner silent") or blend.weight_mpc > 0.0:
            self.level, self.message = OK, "running"
        self.pending.clear()
        self.values = {"weight_mpc": f"{blend.weight_mpc:.3f}"}
        self.pub_blend(cv.blend_to_msg(self.rt, t, blend, record.reference))
        self.pub_ref(cv.reference_to_msg(self.rt, t, record.reference))

    def on_state(self, msg: Any) -> None:
        self.estimate = cv.estimate_from_msg(msg)
        if "msf" in self.pending and self.mode == "combined":
            self.try_blend()
        reference = self.step.reference_between(self.estimate)
        if reference is not None and self.config.simulation.steering_fbl_at_motion_rate:
            self.pub_ref(cv.reference_to_msg(self.rt, self.estimate.t, reference))


class Motion(GraphNode):
    """Motion controller: PI speed control, TDL, feedback EPS → actuator command.

    Runs on every state estimate (100 Hz, the IMU rate) rather than on its own timer, so
    a command follows its sensor sample by one observer hop, as in the lockstep loop.
    """

    name = "motion_controller"

    def __init__(self, rt: Any) -> None:
        super().__init__(rt)
        self.controller = MotionController(self.config.motion, self.config.model_vehicle)
        self.estimate: Optional[StateEstimate] = None
        self.reference: Optional[Reference] = None
        self.delta = 0.0
        self.pub = rt.publisher("moose_msgs/msg/ActuatorCommand", "/control/actuator_command", QOS_DEFAULT)
        rt.subscription("moose_msgs/msg/StateEstimate", "/perception/state", self.on_state, QOS_DEFAULT)
        rt.subscription("moose_msgs/msg/Reference", "/control/reference",
                        lambda m: setattr(self, "reference", cv.reference_from_msg(m)), QOS_DEFAULT)
        rt.subscription("moose_msgs/msg/SteeringReport", "/vehicle/steering",
                        lambda m: setattr(self, "delta", m.delta), QOS_SENSOR)
        self.dt = 1.0 / self.config.simulation.motion_rate_hz

    def on_state(self, msg: Any) -> None:
        self.estimate = cv.estimate_from_msg(msg)
        reference = self.reference or Reference(0.0, self.estimate.vx)
        u = self.controller.step(reference, self.estimate, self.delta, self.dt)
        self.pub(cv.actuator_to_msg(self.rt, self.estimate.t, reference, u))


class CanBridge(GraphNode):
    """CAN bridge: actuator commands → guarded command frames; vehicle frames → the sensor topics.

    The same sensor topics as the simulator's, so the graph cannot tell the difference.
    The bus is polled and the command frames are sent every 10 ms (the command cycle).
    Dropped frames are counted and reported on /diagnostics; a failing send marks a bus
    error (heartbeat state "fault"), and the bus is reopened with a 1 s back-off.
    ``can_log`` writes all traffic in candump format (python-can's ``.log``) or any
    format python-can's Logger knows by its suffix.
    """

    name = "can_bridge"

    def __init__(self, rt: Any) -> None:
        super().__init__(rt)
        import can as pycan

        from moose.canbus.bridge import BridgeCore
        from moose.canbus.safety import GuardParams

        self._can = pycan
        cfg = self.config.vehicle
        self.bridge = BridgeCore(GuardParams(delta_max=cfg.delta_max, torque_max=cfg.T_max,
                                             timeout=float(rt.param("command_timeout", 0.05))))
        self.bus_args = (str(rt.param("can_interface", "udp_multicast")), str(rt.param("can_channel", "239.74.163.2")),
                         rt.param("can_port"))
        self.bus: Any = None
        self.reopen_at = 0.0
        self.open()
        log = rt.param("can_log")
        self.logger = pycan.Logger(str(log)) if log else None
        self.pub = sensor_publishers(rt)
        rt.subscription("moose_msgs/msg/ActuatorCommand", "/control/actuator_command", self.on_command, QOS_DEFAULT)
        rt.timer(0.01, self.tick)

    def open(self) -> None:
        from moose.canbus.bus import open_bus

        interface, channel, port = self.bus_args
        try:
            self.bus = open_bus(interface, channel, port=port)
            self.bridge.bus_error = False
            self.level, self.message = OK, "running"
        except (OSError, self._can.CanError) as exc:
            self.bus, self.bridge.bus_error = None, True
            self.level, self.message = ERROR, f"bus {interface}:{channel} unavailable: {exc}"
            self.reopen_at = time.monotonic() + 1.0

    def on_command(self, msg: Any) -> None:
        from moose.canbus.safety import Command

        self.bridge.on_command(Command(msg.steering_angle, msg.steering_rate, msg.torque_rl, msg.torque_rr), self.rt.now())

    def tick(self) -> None:
        if self.bus is None:
            if time.monotonic() >= self.reopen_at:
                self.open()
            return
        t = self.rt.now()
        try:
            while (frame := self.bus.recv(timeout=0.0)) is not None:
                if self.logger is not None:
                    self.logger(frame)
                sample = self.bridge.on_frame(frame, t)
                if sample is not None:
                    publish, convert = self.pub[type(sample)]
                    publish(convert(self.rt, sample))
            for frame in self.bridge.tick(t):
                self.bus.send(frame)
                if self.logger is not None:
                    self.logger(frame)
        except (OSError, self._can.CanError) as exc:
            self.bridge.bus_error = True
            self.level, self.message = ERROR, f"bus error: {exc}; reopening"
            self.bus.shutdown()
            self.bus, self.reopen_at = None, time.monotonic() + 1.0
            return
        stats = self.bridge.codec.stats
        self.values = {"dropped_frames": stats.dropped, "bad_checksum": stats.bad_checksum,
                       "bad_counter": stats.bad_counter, "command_timeout": self.bridge.guard.timed_out}
        if self.level != ERROR:
            self.level = WARN if self.bridge.guard.timed_out and t > 1.0 else OK
            self.message = "command timeout: safe state" if self.level == WARN else "running"


NODES: dict[str, Callable[[Any], GraphNode]] = {
    "vehicle_simulator": VehicleSimulator,
    "observer": Observer,
    "obstacle_detector": Detector,
    "mpc_planner": lambda rt: Planner(rt, "mpc"),
    "msf_planner": lambda rt: Planner(rt, "msf"),
    "weight_fbl": WeightFbl,
    "motion_controller": Motion,
    "can_bridge": CanBridge,
}
"""Every node of the graph, by executable name."""


def scenario_from_params(rt: Any) -> Any:
    """The scenario named by the node's parameters (``scenario`` or the ad-hoc ``speed``/``tau``/…)."""
    if rt.param("speed") is not None:
        return adhoc_scenario(float(rt.param("speed")), float(rt.param("tau")), float(rt.param("obstacle_half_width")),
                              float(rt.param("obstacle_length", 2.0)), float(rt.param("duration", 8.0)))
    scenario = load_scenario(str(rt.param("scenario", "paper_v7_tau1.4")))
    changes = {k: rt.param(k) for k in ("duration", "mu") if rt.param(k) is not None}
    return dataclasses.replace(scenario, **{k: float(v) for k, v in changes.items()}) if changes else scenario


def parse_overrides(items: Sequence[str]) -> dict[str, Any]:
    """``key=value`` pairs (values parsed as YAML) → parameter overrides."""
    out: dict[str, Any] = {}
    for item in items:
        if "=" not in item:
            raise ParamError(f"--param {item!r} is invalid: expected key=value")
        key, value = item.split("=", 1)
        out[key.strip()] = yaml.safe_load(value)
    return out


def run(name: str, argv: Sequence[str] = ()) -> int:
    """Start node ``name`` and spin it until shutdown; returns the exit status."""
    parser = argparse.ArgumentParser(prog=f"moose node {name}")
    parser.add_argument("--params", help="ROS 2 parameter file")
    parser.add_argument("--param", action="append", default=[], help="parameter override key=value")
    args, _ros_args = parser.parse_known_args(list(argv))
    if name not in NODES:
        raise ParamError(f"node {name!r} is unknown; nodes: {', '.join(sorted(NODES))}")
    rt = create_node(name, args.params, parse_overrides(args.param))
    node = NODES[name](rt)
    node.publish_diagnostics()  # announce: the simulator starts the clock when every node has
    rt.log_info(f"{name} started")
    try:
        rt.spin()
    except KeyboardInterrupt:
        pass
    finally:
        node.message = "stopped"
        rt.shutdown()
    return 0


def _entry(name: str) -> Callable[[], None]:
    def main() -> None:
        try:
            sys.exit(run(name, sys.argv[1:]))
        except ParamError as exc:
            print(f"{name}: error: {exc}", file=sys.stderr)
            sys.exit(2)

    return main


vehicle_simulator_main = _entry("vehicle_simulator")
observer_main = _entry("observer")
obstacle_detector_main = _entry("obstacle_detector")
mpc_planner_main = _entry("mpc_planner")
msf_planner_main = _entry("msf_planner")
weight_fbl_main = _entry("weight_fbl")
motion_controller_main = _entry("motion_controller")
can_bridge_main = _entry("can_bridge")

if __name__ == "__main__":
    if len(sys.argv) < 2:
        print(f"usage: python -m moose_ros.nodes NODE [--params FILE] [--param k=v]; nodes: {', '.join(NODES)}", file=sys.stderr)
        sys.exit(2)
    _entry(sys.argv.pop(1))()
