"""``can_bridge``: actuator commands → guarded command frames; vehicle frames → the sensor topics.

A thin shell around :class:`moose.canbus.runner.BridgeRunner`: the runner owns the bus, the command
guard (the vehicle's limits, the minimum-risk maneuver when commands stop), a dedicated command sender
on the monotonic clock and a bounded receive path; this node forwards commands into it, publishes the
sensor samples it decodes on the same topics the simulator uses (the graph cannot tell the difference)
and its diagnostics on /diagnostics.  A bus that cannot be opened at start is an error (the node does not
start); one that fails later is re-opened after the back-off of :mod:`moose.canbus.health`, and says so on
/diagnostics meanwhile.  With simulated time (``moose launch can``) the runner takes the
node's clock and the command frames go out from the node's 10 ms timer instead of the sender thread.  In lockstep
(:mod:`moose_ros.lockstep`) the bridge handles a tick last: the sensor frames the ECUs sent at tick k (decoded,
stamped k) and the motion controller's commands of tick k, whose frames it then sends; each frame counts in its
marker, and the simulator steps only when they are on its side of the bus.
"""
from __future__ import annotations

import time
from typing import Optional

from moose.canbus.bus import BusParams
from moose.canbus.runner import BridgeParams, BridgeRunner
from moose.canbus.safety import Command, GuardParams
from moose.params import ParamError
from moose.signals import ActuatorCommand

from ..graph import ACTUATOR_COMMAND
from ..lockstep import BUS, BUS_POLL
from ..runtime.base import NodeBase
from .base import GraphNode, sensor_publishers

COMMAND_PERIOD = 0.01
"""The command cycle of config/kanon.dbc (s)."""


class CanBridge(GraphNode):
    """CAN bridge: actuator commands → guarded command frames; vehicle frames → the sensor topics."""

    name = "can_bridge"

    def __init__(self, rt: NodeBase) -> None:
        super().__init__(rt)
        p = self.params
        bus = BusParams(**{k: v for k, v in (("interface", p.can_interface), ("channel", p.can_channel),
                                             ("port", p.can_port)) if v is not None})
        params = BridgeParams(guard=GuardParams.from_vehicle(self.config.vehicle, timeout=p.command_timeout,
                                                         maneuver=self.config.minimum_risk), bus=bus)
        self.simulated = bool(getattr(rt, "use_sim_time", False)) or self.lockstep
        clock = (lambda: self.tick_time or 0.0) if self.lockstep else rt.now if self.simulated else time.monotonic
        self.runner = BridgeRunner(params, log=p.can_log, clock=clock)
        if self.runner.open_error is not None:  # at start: a bridge without its bus refuses to start
            why = self.runner.open_error
            self.runner.close()
            raise ParamError(f"can_interface {bus.interface!r}, can_channel {bus.channel!r}: the bus cannot be "
                             f"opened ({why}); the bridge does not start without its bus")
        self.pub = sensor_publishers(self, self.stamp_time())
        self.subscribe(ACTUATOR_COMMAND, self.on_command)
        if self.join is not None:  # the bus is read by the tick join, the frames go out in the tick
            self.join.add(BUS)
            rt.timer(BUS_POLL, self._pump)
        else:
            rt.timer(COMMAND_PERIOD, self.tick)
        if not self.simulated:
            self.runner.start()  # the sender thread, real time; this thread runs the callbacks

    def on_inputs(self, stale: dict[str, Optional[float]], now: float) -> None:
        """The commands are the guard's to supervise: it runs the minimum-risk maneuver and says so."""

    def on_command(self, command: ActuatorCommand) -> None:
        c = command
        self.runner.command(Command(c.steering_angle, c.steering_rate, c.torque_rl, c.torque_rr))

    def tick(self) -> None:
        if self.simulated:
            self.runner.send_due()
        for sample in self.runner.receive(stamp=self.rt.now()):
            self.forward(sample)
        self.report()

    def forward(self, sample: object) -> None:
        """Publish a decoded sensor sample on its topic."""
        publish, convert = self.pub[type(sample)]
        publish(convert(self.rt, sample))

    def report(self) -> None:
        diagnostics = self.runner.diagnostics()
        self.level, self.message, self.values = diagnostics.level, diagnostics.message, diagnostics.values

    # -- lockstep ------------------------------------------------------------------------------

    def poll(self) -> None:
        """The frames on the bus go to the tick join; each is decoded when its tick is handed over."""
        assert self.join is not None
        for frame in self.runner.read(self.tick_time or 0.0):
            if not self.runner.core.codec.own(frame):  # the multicast bus echoes our own frames
                self.join.message(BUS, lambda frame=frame: self.decoded(frame))

    def decoded(self, frame: object) -> None:
        t = self.now()
        sample = self.runner.decode(frame, t, stamp=t)  # type: ignore[arg-type]
        if sample is not None:
            self.forward(sample)

    def on_tick(self, t: float) -> None:
        """The command of the tick goes out as frames (the guard's output at t), each announced in the marker."""
        for _ in range(self.runner.send_due(t)):
            self.announce(BUS)
        self.report()

    def close(self) -> None:
        self.runner.close()
