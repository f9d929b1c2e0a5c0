"""``motion_controller``: PI speed control, torque distribution law, feedback EPS → actuator command; and the
minimum-risk maneuver when the stack can no longer drive the car."""
from __future__ import annotations

from typing import Optional

from moose.minimum_risk import ActuatorLimits, Command, MinimumRiskManeuver
from moose.motion import MotionController
from moose.signals import EpsSample, Reference, StateEstimate
from moose.state import STEER_RATE, TORQUE_RL, TORQUE_RR
from moose.timing import SteeringPredictor

from .. import convert as cv
from ..graph import (
    ACTUATOR_COMMAND,
    CONTROL_LAG_MAX,
    DIAGNOSTICS,
    REFERENCE,
    STATE,
    STEERING,
    WHEEL_SPEEDS,
    essential_upstream,
)
from ..runtime.base import NodeBase
from .base import ERROR, WARN, GraphNode

NEEDED = (STATE, REFERENCE, STEERING)
"""Inputs without which the controller cannot drive: the estimate, the reference, the measured steering angle."""


class Motion(GraphNode):
    """Motion controller: PI speed control, TDL, feedback EPS → actuator command.

    Runs on every state estimate (100 Hz, the IMU rate) rather than on its own timer, so a command
    follows its sensor sample by one observer hop, as in the lockstep loop.

    **Minimum-risk maneuver.**  Every supervision cycle (100 Hz on the node's clock) it checks that it can
    drive: the estimate, the reference and the measured steering angle within their deadlines, and every
    node it cannot do without (:func:`moose_ros.graph.essential_upstream`: observer, detector, weight_fbl,
    the sensor source) neither reporting ERROR on /diagnostics nor silent there for longer than the topic's
    deadline.  If not, it stops following the reference and commands the minimum-risk maneuver
    (:class:`moose.minimum_risk.MinimumRiskManeuver`, the CAN bridge's law) from its last command, the
    steering angle and the rear wheel speeds, once per cycle, and reports ERROR with the reasons.  When
    everything is fresh and healthy again it resumes control (the speed loop restarts from the car's speed).
    An estimate older than :data:`~moose_ros.graph.CONTROL_LAG_MAX` when it arrives is a deadline miss; one
    older than its topic's deadline is not acted on.
    """

    name = "motion_controller"

    def __init__(self, rt: NodeBase) -> None:
        super().__init__(rt)
        self.controller = MotionController(self.config.motion, self.config.model_vehicle)
        self.estimate: Optional[StateEstimate] = None
        self.reference: Optional[Reference] = None
        self.cruise = Reference(0.0, self.params.load_scenario().v_init)
        """The reference before the first plan acts: straight on at the approach speed (the lockstep loop's)."""
        self.delta = 0.0
        self.delta_stamp = 0.0
        """The measured steering angle and its sample's time."""
        vehicle, timing = self.config.vehicle, self.config.timing
        self.eps = (SteeringPredictor(timing.command_delay_s, self.config.motion_period, vehicle.delta_max,
                                      vehicle.delta_rate_max) if timing.compensate else None)
        """``timing.compensate``: the EPS loop closes on the angle its command will meet (the lockstep loop's)."""
        self.omega: Optional[float] = None
        self.dt = 1.0 / self.config.simulation.motion_rate_hz
        self.maneuver = MinimumRiskManeuver(self.config.minimum_risk, ActuatorLimits.from_vehicle(self.config.vehicle),
                                            self.dt)
        self.last = Command(0.0, 0.0, 0.0, 0.0)
        """The last command published."""
        self.reasons: list[str] = []
        """Why the minimum-risk maneuver runs (empty: the controller drives)."""
        self.upstream = essential_upstream(self.name)
        self.health: dict[str, tuple[int, str, float]] = {}
        """Each essential upstream node's last status on /diagnostics: (level, message, arrival on our clock)."""
        self.late = 0
        self.pub = self.publisher(ACTUATOR_COMMAND)
        self.subscribe(STATE, self.on_state)
        self.subscribe(REFERENCE, lambda reference: setattr(self, "reference", reference))
        self.subscribe(STEERING, self.on_steering)
        self.subscribe(WHEEL_SPEEDS, lambda sample: setattr(self, "omega", 0.5 * (sample.omega_rl + sample.omega_rr)))
        self.subscribe(DIAGNOSTICS, self.on_diagnostics)

    def on_diagnostics(self, statuses: list[tuple[str, int, str]]) -> None:
        for name, level, message in statuses:
            if name in self.upstream:
                self.health[name] = (level, message, self.clock())

    def on_steering(self, sample: EpsSample) -> None:
        self.delta, self.delta_stamp = sample.delta, sample.t

    def on_state(self, estimate: StateEstimate) -> None:
        self.estimate = estimate
        if not self.lockstep:
            self.command(estimate)

    def on_tick(self, t: float) -> None:
        """Lockstep: the command of the tick, from its estimate, reference and steering angle (the lockstep loop's)."""
        if self.estimate is not None:
            self.command(self.estimate)

    def command(self, estimate: StateEstimate) -> None:
        """Command from ``estimate`` with the newest reference and steering angle."""
        now = self.now()
        lag = now - estimate.t
        if lag > CONTROL_LAG_MAX + 1e-9:
            self.deadline_misses += 1
            self.late += 1
        if self.reasons or lag > STATE.deadline + 1e-9:  # type: ignore[operator]
            return
        reference = self.reference or self.cruise
        if self.eps is None:
            u = self.controller.step(reference, estimate, self.delta, self.dt)
        else:
            u = self.controller.step(reference, estimate, self.eps.predict(self.delta, self.delta_stamp, now), self.dt)
            self.eps.record(now, float(u[STEER_RATE]))
        self.last = Command(reference.delta, float(u[STEER_RATE]), float(u[TORQUE_RL]), float(u[TORQUE_RR]))
        self.pub(cv.actuator_to_msg(self.rt, estimate.t, reference, u))

    def on_inputs(self, stale: dict[str, Optional[float]], now: float) -> None:
        self.report_stale(stale, ERROR, {WHEEL_SPEEDS.name: WARN})
        reasons = [f"{t.name} stale" for t in NEEDED if t.name in stale]
        for node, (level, _message, arrival) in sorted(self.health.items()):
            if level >= ERROR:
                reasons.append(f"{node} reports an error")
            elif now - arrival > DIAGNOSTICS.deadline:  # type: ignore[operator]
                reasons.append(f"{node} silent on /diagnostics for {now - arrival:.1f} s")
        self.values = {"late_estimates": self.late}
        if reasons:
            if not self.reasons:
                self.maneuver.reset()
            self.reasons = reasons
            self.minimum_risk(now, stale)
        elif self.reasons:
            self.reasons = []
            self.problem("minimum_risk", None)
            self.controller.reset(torque=self.last.torque_rl)  # the speed loop restarts from the car's speed

    def minimum_risk(self, now: float, stale: dict[str, Optional[float]]) -> None:
        """One cycle of the minimum-risk maneuver, from the last command and what is still measured fresh."""
        angle = None if STEERING.name in stale else self.delta
        omega = None if WHEEL_SPEEDS.name in stale else self.omega
        self.last = out = self.maneuver.step(self.last, angle, omega)
        state = "stopped by" if self.maneuver.stopped else "running"
        self.problem("minimum_risk", ERROR, f"{state} the minimum-risk maneuver: {'; '.join(self.reasons)}")
        self.pub(cv.actuator_to_msg(self.rt, now, Reference(out.steering_angle, 0.0),
                                    (out.steering_rate, out.torque_rl, out.torque_rr)))
