"""``can_bridge``: actuator commands → guarded command frames; vehicle frames → the sensor topics."""
from __future__ import annotations

import time
from typing import Any

import can

from moose.canbus.bridge import BridgeCore
from moose.canbus.bus import DEFAULT_GROUP
from moose.canbus.safety import Command, GuardParams
from moose.signals import ActuatorCommand

from ..graph import ACTUATOR_COMMAND
from .base import ERROR, OK, WARN, GraphNode, sensor_publishers


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
        cfg = self.config.vehicle
        self.bridge = BridgeCore(GuardParams(delta_max=cfg.delta_max, torque_max=cfg.T_max,
                                             timeout=self.params.command_timeout))
        self.bus: Any = None
        self.reopen_at = 0.0
        self.open()
        self.logger = can.Logger(self.params.can_log) if self.params.can_log else None
        self.pub = sensor_publishers(rt)
        self.subscribe(ACTUATOR_COMMAND, self.on_command)
        rt.timer(0.01, self.tick)

    def open(self) -> None:
        p = self.params
        try:
            self.bus = p.open_bus(self.name)
            self.bridge.bus_error = False
            self.level, self.message = OK, "running"
        except (OSError, can.CanError) as exc:
            self.bus, self.bridge.bus_error = None, True
            self.level, self.message = ERROR, f"bus {p.can_interface}:{p.can_channel or DEFAULT_GROUP} unavailable: {exc}"
            self.reopen_at = time.monotonic() + 1.0

    def on_command(self, command: ActuatorCommand) -> None:
        c = command
        self.bridge.on_command(Command(c.steering_angle, c.steering_rate, c.torque_rl, c.torque_rr), self.rt.now())

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
        except (OSError, can.CanError) as exc:
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

