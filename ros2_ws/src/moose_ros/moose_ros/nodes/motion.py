"""``motion_controller``: PI speed control, torque distribution law, feedback EPS → actuator command."""
from __future__ import annotations

from typing import Any, Optional

from moose.motion import MotionController
from moose.signals import Reference, StateEstimate

from .. import convert as cv
from ..graph import ACTUATOR_COMMAND, REFERENCE, STATE, STEERING
from .base import GraphNode


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
        self.pub = ACTUATOR_COMMAND.publisher(rt)
        self.subscribe(STATE, self.on_state)
        self.subscribe(REFERENCE, lambda reference: setattr(self, "reference", reference))
        self.subscribe(STEERING, lambda sample: setattr(self, "delta", sample.delta))
        self.dt = 1.0 / self.config.simulation.motion_rate_hz

    def on_state(self, estimate: StateEstimate) -> None:
        self.estimate = estimate
        reference = self.reference or Reference(0.0, self.estimate.vx)
        u = self.controller.step(reference, self.estimate, self.delta, self.dt)
        self.pub(cv.actuator_to_msg(self.rt, self.estimate.t, reference, u))

