"""``observer``: the state observer — IMU, GPS, wheel speeds, EPS → /perception/state and odom → base_link on
/tf at the IMU rate."""
from __future__ import annotations

from typing import Any, Optional

from moose.observer import StateObserver
from moose.signals import StateEstimate
from moose.state import X
from moose.vehicle import initial_state

from .. import convert as cv
from ..graph import GPS, IMU, STATE, STEERING, TF, WHEEL_SPEEDS
from .base import ERROR, WARN, GraphNode


class Observer(GraphNode):
    """State observer: IMU, GPS, wheel speeds, EPS → /perception/state at the IMU rate."""

    name = "observer"

    def __init__(self, rt: Any) -> None:
        super().__init__(rt)
        scenario = self.params.load_scenario()
        start = initial_state(self.config.vehicle, x=scenario.start_x, vx=scenario.v_init)
        self.observer = StateObserver(self.config.observer, self.config.model_vehicle,
                                      StateEstimate(0.0, start[X], 0.0, 0.0, scenario.v_init, 0.0, 0.0, 0.0))
        self.pub = STATE.publisher(rt)
        self.pub_tf = TF.publisher(rt)
        self.dropped = 0
        self.subscribe(IMU, lambda sample: self.feed(sample, True))
        for topic in (GPS, WHEEL_SPEEDS, STEERING):
            self.subscribe(topic, self.feed)

    def on_inputs(self, stale: dict[str, Optional[float]], now: float) -> None:
        """The 100 Hz sensors are needed (without the IMU no estimate is published at all; without the wheel
        speeds or the steering angle the estimate drifts): ERROR.  A late GPS fix only degrades (WARN)."""
        self.report_stale(stale, ERROR, {GPS.name: WARN})

    def feed(self, sample: Any, publish: bool = False) -> None:
        try:
            self.observer.update(sample)
        except ValueError:
            self.dropped += 1  # out of order (transport reordering): counted, never fatal
            self.level, self.message, self.values = WARN, "out-of-order samples dropped", {"dropped": self.dropped}
            return
        if publish:
            estimate = self.observer.estimate()
            self.pub(cv.estimate_to_msg(self.rt, estimate))
            self.pub_tf(cv.estimate_tf(self.rt, estimate))
