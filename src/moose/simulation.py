"""Lockstep closed-loop simulation of Fig. 3: plant, sensors, perception, planning, control.

Rates (``SimulationParams``): the plant is integrated at 1 kHz; sensors,
observer, detector and motion control run at 100 Hz (GPS at 1 Hz with its lag);
MPC, MSF, the weight function and the FBL run at 5 Hz, the MicroLabBox's rate,
and re-plan at once when the detector reports a new obstacle (the 5 Hz phase
restarts there).  Each planning instant uses the estimate of that instant and its result acts
from that motion tick on (zero compute latency in lockstep; the node graph has
the real one).  All randomness comes from one seeded generator, so a run is
a function of (configuration, scenario, planner mode, seed) — except a planning
step whose wall-clock solve time exceeds the MPC's time budget, which is then
reported ``over_budget``.
"""
from __future__ import annotations

import dataclasses
from typing import Optional

import numpy as np

from .config import Config, PlannerMode
from .detector import ObstacleDetector
from .fbl import FeedbackLinearization
from .maneuver import MaxSteeringTable
from .motion import MotionController
from .mpc import MpcPlanner
from .msf import MsfPlanner
from .observer import StateObserver
from .params import replace
from .scenario import Scenario
from .sensors import Sensors
from .signals import Blend, EpsSample, PlannerInput, PlanResult, Reference, StateEstimate, Threat
from .vehicle import VehiclePlant, initial_state
from .weight import WeightFunction

TRACE_FIELDS = (
    "t", "x", "y", "theta", "vx", "vy", "gamma", "delta", "omega_rl", "omega_rr",
    "x_hat", "y_hat", "theta_hat", "vx_hat", "vy_hat", "gamma_hat",
    "delta_ref", "delta_mpc", "vx_ref", "weight_mpc", "u_delta_rate", "u_T_rl", "u_T_rr", "threat",
)
"""Columns of :attr:`SimulationResult.trace`, sampled at the motion-control rate."""


@dataclasses.dataclass(frozen=True)
class PlanningRecord:
    """One 5 Hz planning instant."""

    t: float
    threat: Optional[Threat]
    mpc: Optional[PlanResult]
    msf: Optional[PlanResult]
    blend: Blend
    reference: Reference
    delta_mpc: float
    """δ* the FBL computes from the MPC's own first acceleration (the paper's δ_MPC)."""


@dataclasses.dataclass
class SimulationResult:
    """Everything a run produced."""

    scenario: Scenario
    planner: PlannerMode
    seed: int
    trace: dict[str, np.ndarray]
    planning: list[PlanningRecord]
    first_threat: Optional[Threat]
    samples: list = dataclasses.field(default_factory=list)
    """Every sensor sample delivered to the observer, in order (for bags and replay)."""
    estimates: list = dataclasses.field(default_factory=list)
    """The observer's estimate at each motion tick."""
    threats: list = dataclasses.field(default_factory=list)
    """(t, threat or None) at each motion tick."""


@dataclasses.dataclass
class _Row:
    delta_ref: float = 0.0
    delta_mpc: float = 0.0
    vx_ref: float = 0.0
    weight_mpc: float = float("nan")


class ClosedLoop:
    """The moose test in lockstep: build once, :meth:`run` once."""

    def __init__(
        self,
        config: Config,
        scenario: Scenario,
        planner: PlannerMode | None = None,
        seed: int = 0,
        table: MaxSteeringTable | None = None,
    ) -> None:
        vehicle = config.vehicle if scenario.mu is None else replace(config.vehicle, mu=scenario.mu)
        self.config = dataclasses.replace(config, vehicle=vehicle)
        self.scenario = scenario
        self.mode: PlannerMode = planner or config.simulation.planner
        self.seed = seed
        sim = config.simulation
        self.table = table if table is not None else MaxSteeringTable.build(vehicle, config.maneuver)
        self.plant = VehiclePlant(vehicle, dt=sim.plant_dt)
        self.sensors = Sensors(config.sensors, vehicle, np.random.default_rng(seed))
        self.detector = ObstacleDetector(config.detector, self.table)
        self.mpc = MpcPlanner(config.mpc, vehicle) if self.mode != "msf" else None
        self.msf = MsfPlanner(config.msf, self.table, vehicle) if self.mode != "mpc" else None
        self.weight = WeightFunction(config.weight, vehicle)
        self.fbl = FeedbackLinearization(config.fbl, vehicle)
        self.motion = MotionController(config.motion, vehicle)
        x0 = initial_state(vehicle, x=scenario.start_x, vx=scenario.v_init)
        self.plant.reset(x0)
        self.observer = StateObserver(config.observer, vehicle, initial=_estimate_of(0.0, x0))

    def run(self) -> SimulationResult:
        sim = self.config.simulation
        dt_motion = 1.0 / sim.motion_rate_hz
        n_motion = int(round((self.scenario.lead_time + self.scenario.duration) * sim.motion_rate_hz))
        trace = np.full((n_motion + 1, len(TRACE_FIELDS)), np.nan)
        planning: list[PlanningRecord] = []
        appeared = False
        first_threat: Optional[Threat] = None
        guess: Optional[np.ndarray] = None
        applied = np.zeros(2)
        reference = Reference(delta=0.0, vx=self.scenario.v_init)
        row = _Row(vx_ref=self.scenario.v_init)
        delta_meas = 0.0
        u = np.zeros(3)
        threat: Optional[Threat] = None
        next_plan = 0
        samples: list = []
        estimates: list = []
        threats: list = []
        for k in range(n_motion + 1):
            t = k * dt_motion
            state = self.plant.state
            specific_force = self.plant.specific_force if k else self.plant.imu_specific_force(state, u)
            for sample in self.sensors.sample(t, state, specific_force):
                samples.append(sample)
                self.observer.update(sample)
                if isinstance(sample, EpsSample):
                    delta_meas = sample.delta
            estimate = self.observer.estimate()
            estimates.append(estimate)
            appeared = appeared or state[0] >= self.scenario.x_appear
            visible = [self.scenario.danger_zone] if appeared else []
            previous = threat
            threat = self.detector.update(t, estimate, visible)
            threats.append((t, threat))
            if threat is not None and first_threat is None:
                first_threat = threat
            new_obstacle = threat is not None and (previous is None or previous.obstacle != threat.obstacle)
            planned = k >= next_plan or new_obstacle
            if planned:
                next_plan = k + sim.motion_steps_per_plan
                record = self._plan(t, estimate, threat, guess)
                planning.append(record)
                guess = self.weight.next_initial_guess(record.blend)
                applied = record.blend.accel[0]
                reference = record.reference
                row = _Row(reference.delta, record.delta_mpc, reference.vx, record.blend.weight_mpc)
            if sim.steering_fbl_at_motion_rate and not planned:
                held = self.fbl.reference(applied, estimate)
                reference = Reference(delta=held.delta, vx=reference.vx)
                row.delta_ref = reference.delta
            u = self.motion.step(reference, estimate, delta_meas, dt_motion)
            trace[k] = (
                t, *state[:6], state[8], state[6], state[7],
                estimate.x, estimate.y, estimate.theta, estimate.vx, estimate.vy, estimate.gamma,
                row.delta_ref, row.delta_mpc, row.vx_ref, row.weight_mpc, *u, float(threat is not None),
            )
            if k < n_motion:
                self.plant.step(u, sim.plant_steps_per_motion)
        columns = {name: trace[:, i].copy() for i, name in enumerate(TRACE_FIELDS)}
        return SimulationResult(self.scenario, self.mode, self.seed, columns, planning, first_threat,
                                samples, estimates, threats)

    def _plan(
        self, t: float, estimate: StateEstimate, threat: Optional[Threat], guess: Optional[np.ndarray]
    ) -> PlanningRecord:
        inp = PlannerInput(t=t, estimate=estimate, threat=threat, v_des=self.scenario.v_des, initial_guess=guess, y_lane=0.0)
        mpc = self.mpc.plan(inp) if self.mpc is not None else None
        msf = self.msf.plan(inp) if self.msf is not None else None
        if self.mode == "combined":
            assert mpc is not None and msf is not None
            blend = self.weight.blend(mpc, msf, threat, estimate)
        elif self.mode == "mpc":
            assert mpc is not None
            blend = Blend(weight_mpc=1.0, accel=mpc.accel)
        else:
            assert msf is not None
            blend = Blend(weight_mpc=0.0, accel=msf.accel)
        reference = self.fbl.reference(blend.accel[0], estimate)
        delta_mpc = self.fbl.reference(mpc.accel[0], estimate).delta if mpc is not None else float("nan")
        return PlanningRecord(t, threat, mpc, msf, blend, reference, delta_mpc)


def _estimate_of(t: float, state: np.ndarray) -> StateEstimate:
    """The true state as an estimate: the observer's initial condition (the car starts surveyed)."""
    return StateEstimate(
        t=t, x=float(state[0]), y=float(state[1]), theta=float(state[2]), vx=float(state[3]),
        vy=float(state[4]), gamma=float(state[5]), delta=float(state[8]),
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
