"""``observer``: the state observer — IMU, GPS, wheel speeds, EPS → /perception/state and odom → base_link on
/tf at the IMU rate."""
from __future__ import annotations

from typing import Optional

from moose.observer import StateObserver
from moose.signals import Sample, StateEstimate
from moose.state import X
from moose.vehicle import initial_state

from .. import convert as cv
from ..graph import GPS, IMU, STATE, STEERING, TF, WHEEL_SPEEDS
from ..runtime.base import NodeBase
from .base import ERROR, WARN, GraphNode


class Observer(GraphNode):
    """State observer: IMU, GPS, wheel speeds, EPS → /perception/state at the IMU rate (in lockstep: once per tick,
    after every sample the tick delivered)."""

    name = "observer"

    def __init__(self, rt: NodeBase) -> None:
        super().__init__(rt)
        scenario = self.params.load_scenario()
        start = initial_state(self.config.vehicle, x=scenario.start_x, vx=scenario.v_init)
        self.observer = StateObserver(self.config.observer, self.config.model_vehicle,
                                      StateEstimate(0.0, start[X], 0.0, 0.0, scenario.v_init, 0.0, 0.0, 0.0))
        self.pub = self.publisher(STATE)
        self.pub_tf = self.publisher(TF)
        self.dropped = 0
        self.batch: list[Sample] = []
        """Lockstep: the samples the tick delivered, fused together at its end (``update_all``, as the loop)."""
        if self.lockstep:
            for topic in (IMU, GPS, WHEEL_SPEEDS, STEERING):
                self.subscribe(topic, self.batch.append)
        else:
            self.subscribe(IMU, lambda sample: self.feed(sample, True))
            for topic in (GPS, WHEEL_SPEEDS, STEERING):
                self.subscribe(topic, self.feed)

    def on_inputs(self, stale: dict[str, Optional[float]], now: float) -> None:
        """The 100 Hz sensors are needed (without the IMU no estimate is published at all; without the wheel
        speeds or the steering angle the estimate drifts): ERROR.  A late GPS fix only degrades (WARN)."""
        self.report_stale(stale, ERROR, {GPS.name: WARN})

    def feed(self, sample: Sample, publish: bool = False) -> None:
        if self.fuse([sample]) and publish:
            self.publish()

    def fuse(self, samples: list[Sample]) -> bool:
        """Fuse ``samples`` in order; False if one was refused (out of order: transport reordering), which is
        counted, never fatal."""
        try:
            self.observer.update_all(samples)
        except ValueError:
            self.dropped += 1
            self.level, self.message, self.values = WARN, "out-of-order samples dropped", {"dropped": self.dropped}
            return False
        return True

    def publish(self) -> None:
        estimate = self.observer.estimate()
        self.pub(cv.estimate_to_msg(self.rt, estimate))
        self.pub_tf(cv.estimate_tf(self.rt, estimate))

    def on_tick(self, t: float) -> None:
        """Lockstep: the estimate after every sample delivered at the tick, once per tick (as the lockstep loop's)."""
        batch, self.batch[:] = list(self.batch), []
        self.fuse(batch)
        self.publish()
