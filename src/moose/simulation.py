"""Lockstep closed-loop simulation of Fig. 3: plant, sensors, perception, planning, control.

Rates (``SimulationParams``): the plant is integrated at 1 kHz; sensors,
observer, detector and motion control run at 100 Hz (GPS at 1 Hz with its lag);
MPC, MSF, the weight function and the FBL run every t_s = 0.2 s (5 Hz, the
MicroLabBox's rate; :class:`moose.planner.step.PlanningStep`), and re-plan at once
when the detector reports a new obstacle (the planning period restarts there).
Each planning instant uses the estimate of that instant.  The car's latency chain
(``timing``, :mod:`moose.timing`) is applied where the car has it: the samples
reach the observer ``sensor_delay_s`` after the sensors hand them over, a plan acts
``planning_delay_s`` after its instant (inside the planning step), and a command
acts on the actuators ``command_delay_s`` after it was computed.  All randomness
comes from one seeded generator and no step reads the wall clock (the MPC's budget
is charged the planning delay), so a run is a function of (configuration,
scenario, planner mode, seed).
"""
from __future__ import annotations

import dataclasses
import math
from typing import Optional

import numpy as np

from .detector import ObstacleDetector
from .maneuver import MaxSteeringTable
from .motion import MotionController
from .observer import StateObserver
from .planner.step import PlanningRecord, PlanningStep, new_obstacle
from .scenario import Scenario
from .schema import Config, PlannerMode
from .sensors import Sensors
from .signals import EpsSample, Obstacle, Reference, StateEstimate, Threat
from .state import DELTA, GAMMA, OMEGA_RL, OMEGA_RR, STEER_RATE, THETA, VX, VY, X, Y
from .timing import CommandHold, DelayLine, SteeringPredictor
from .vehicle import VehiclePlant, initial_state

TRACE_FIELDS = (
    "t", "x", "y", "theta", "vx", "vy", "gamma", "delta", "omega_rl", "omega_rr",
    "x_hat", "y_hat", "theta_hat", "vx_hat", "vy_hat", "gamma_hat",
    "delta_ref", "delta_mpc", "vx_ref", "weight_mpc", "u_delta_rate", "u_T_rl", "u_T_rr", "threat",
)
"""Columns of :attr:`SimulationResult.trace`, sampled at the motion-control rate."""


@dataclasses.dataclass
class SimulationResult:
    """Everything a run produced."""

    scenario: Scenario
    planner: PlannerMode
    seed: int
    trace: dict[str, np.ndarray]
    planning: list[PlanningRecord]
    first_threat: Optional[Threat]
    config: Config
    """The configuration of the run, with the road's μ in ``vehicle.mu`` (the scenario's, if it sets one)."""
    end_time: float
    """Time the run was planned to end (s): lead time + duration."""
    samples: list = dataclasses.field(default_factory=list)
    """Every sensor sample delivered to the observer, in order (for bags and replay)."""
    estimates: list = dataclasses.field(default_factory=list)
    """The observer's estimate at each motion tick."""
    threats: list = dataclasses.field(default_factory=list)
    """(t, threat or None) at each motion tick."""


class ClosedLoop:
    """The moose test in lockstep: build once, :meth:`run` once.

    The road's μ is the scenario's when it sets one, else ``vehicle.mu``; the stack assumes the
    planning μ (:attr:`moose.schema.Config.mu_planning`), which equals the road's unless
    ``planning.mu_estimate`` sets a deliberate mismatch.
    """

    def __init__(
        self,
        config: Config,
        scenario: Scenario,
        planner: PlannerMode | None = None,
        seed: int = 0,
        table: MaxSteeringTable | None = None,
    ) -> None:
        self.config = config = scenario.configure(config)
        vehicle = config.vehicle
        self.scenario = scenario
        self.mode: PlannerMode = planner or config.simulation.planner
        self.seed = seed
        model = config.model_vehicle
        self.table = table if table is not None else MaxSteeringTable.build(model, config.maneuver)
        if self.table.mu != model.mu:
            raise ValueError(f"table.mu = {self.table.mu!r} is invalid: the planning μ is {model.mu!r}")
        self.plant = VehiclePlant(vehicle, dt=config.simulation.plant_dt)
        self.sensors = Sensors(config.sensors, vehicle, np.random.default_rng(seed))
        self.detector = ObstacleDetector(config.detector, self.table)
        self.step = PlanningStep(config, self.mode, self.table)
        self.motion = MotionController(config.motion, model)
        x0 = initial_state(vehicle, x=scenario.start_x, vx=scenario.v_init)
        self.plant.reset(x0)
        self.observer = StateObserver(config.observer, model, initial=_estimate_of(0.0, x0))

    def run(self) -> SimulationResult:
        sim, timing = self.config.simulation, self.config.timing
        dt_motion = self.config.motion_period
        end_time = self.scenario.end_time
        n_motion = int(round(end_time * sim.motion_rate_hz))
        rows: list[tuple[float, ...]] = []
        planning: list[PlanningRecord] = []
        appeared = False
        first_threat: Optional[Threat] = None
        reference = Reference(delta=0.0, vx=self.scenario.v_init)
        delta_meas, delta_stamp = 0.0, 0.0
        u = np.zeros(3)
        threat: Optional[Threat] = None
        next_plan = 0
        samples: list = []
        estimates: list = []
        threats: list = []
        # the world's side of the latency chain: sensors → observer, commands → actuators (moose.timing)
        in_transit: DelayLine = DelayLine(timing.sensor_delay_s, dt_motion)
        actuators: CommandHold[np.ndarray] = CommandHold(timing.command_delay_s, dt_motion)
        vehicle = self.config.vehicle
        eps = (SteeringPredictor(timing.command_delay_s, dt_motion, vehicle.delta_max, vehicle.delta_rate_max)
               if timing.compensate else None)
        # the blocks' methods, looked up once (the loop runs 100 times per simulated second)
        plant, observe, sense, detect = self.plant, self.observer.update_all, self.sensors.sample, self.detector.update
        estimate_now, reference_at, control = self.observer.estimate, self.step.reference_at, self.motion.step
        send, receive, actuate, act = in_transit.push, in_transit.pop_due, actuators.push, actuators.acting
        step = self.step
        steps_per_motion, steps_per_plan = sim.plant_steps_per_motion, self.config.motion_steps_per_plan
        seen: list[Obstacle] = [self.scenario.danger_zone]
        unseen: list[Obstacle] = []
        for k in range(n_motion + 1):
            t = k * dt_motion
            state = plant.state
            specific_force = plant.specific_force if k else plant.imu_specific_force(state, u)
            for sample in sense(t, state, specific_force):
                send(t, sample)
            delivered = receive(t)
            samples.extend(delivered)
            observe(delivered)
            for sample in delivered:
                if type(sample) is EpsSample:
                    delta_meas, delta_stamp = sample.delta, sample.t
            estimate = estimate_now()
            estimates.append(estimate)
            true = state.tolist()
            appeared = appeared or self.scenario.appears(true[X], true[VX])
            previous = threat
            threat = detect(t, estimate, seen if appeared else unseen)
            threats.append((t, threat))
            if threat is not None and first_threat is None:
                first_threat = threat
            replan = new_obstacle(previous, threat)
            if k >= next_plan or replan:
                next_plan = k + steps_per_plan
                v_des = self.scenario.desired_speed(first_threat is not None)
                planning.append(step.plan(t, estimate, threat, v_des))
            reference = reference_at(t, estimate) or reference
            acting = step.acting
            if eps is None:
                command = control(reference, estimate, delta_meas, dt_motion)
            else:  # the EPS loop closes on the angle its command will meet (timing.compensate)
                command = control(reference, estimate, eps.predict(delta_meas, delta_stamp, t), dt_motion)
                eps.record(t, float(command[STEER_RATE]))
            actuate(t, command)
            u = act(t)
            rows.append((
                t, true[X], true[Y], true[THETA], true[VX], true[VY], true[GAMMA],
                true[DELTA], true[OMEGA_RL], true[OMEGA_RR],
                estimate.x, estimate.y, estimate.theta, estimate.vx, estimate.vy, estimate.gamma,
                reference.delta, acting.delta_mpc if acting is not None else 0.0, reference.vx,
                acting.blend.weight_mpc if acting is not None else math.nan, *u.tolist(), float(threat is not None),
            ))
            if k < n_motion:
                plant.step(u, steps_per_motion)
        trace = np.array(rows, dtype=float)
        columns = {name: trace[:, i].copy() for i, name in enumerate(TRACE_FIELDS)}
        return SimulationResult(self.scenario, self.mode, self.seed, columns, planning, first_threat,
                                self.config, end_time,
                                samples, estimates, threats)


def _estimate_of(t: float, state: np.ndarray) -> StateEstimate:
    """The true state as an estimate: the observer's initial condition (the car starts surveyed)."""
    return StateEstimate(
        t=t, x=float(state[X]), y=float(state[Y]), theta=float(state[THETA]), vx=float(state[VX]),
        vy=float(state[VY]), gamma=float(state[GAMMA]), delta=float(state[DELTA]),
    )


def simulate(
    config: Config,
    scenario: Scenario,
    planner: PlannerMode | None = None,
    seed: int = 0,
    table: MaxSteeringTable | None = None,
) -> SimulationResult:
    """Run one moose test in lockstep and return its trace and planning log."""
    return ClosedLoop(config, scenario, planner, seed, table).run()
