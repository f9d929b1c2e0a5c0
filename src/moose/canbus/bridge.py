"""Bridge core: actuator commands → guarded command frames; vehicle frames → sensor samples.

Pure logic, time passed in.  ``on_command`` takes the motion controller's command;
``tick(t)`` returns the frames due at t (CMD_STEER and CMD_TORQUE every 10 ms through the
:class:`~moose.canbus.safety.CommandGuard`, BRIDGE_HEARTBEAT and BRIDGE_STATUS every
100 ms); ``on_frame`` validates a received frame and returns the core's sample record, or
``None`` — a dropped frame is counted in ``codec.stats``, an error frame goes to
``health`` — and never raises.  The python-can I/O around it is
:class:`moose.canbus.bus.BusLink`.
"""
from __future__ import annotations

from typing import Optional, Union

import can

from moose.signals import EpsSample, GpsSample, ImuSample, WheelSpeedSample

from .codec import Codec
from .health import BusHealth, BusState, HealthParams
from .safety import Command, CommandGuard, GuardParams

Sample = Union[ImuSample, GpsSample, WheelSpeedSample, EpsSample]

COMMAND_PERIOD = 0.01
STATUS_PERIOD = 0.1
HEARTBEAT_STATE = {"commanding": 0, "safe_state": 1, "fault": 2}


class BridgeCore:
    """The bridge between the motion controller and the vehicle bus (config/kanon.dbc)."""

    def __init__(self, guard: GuardParams = GuardParams(), codec: Optional[Codec] = None,
                 health: HealthParams = HealthParams()) -> None:
        self.codec = codec or Codec(node="BRIDGE")
        self.guard = CommandGuard(guard)
        self.health = BusHealth(health)
        self._external_bus_error = False
        self._next = {"command": 0.0, "status": 0.0}
        self._alive = 0
        self._gps_position: Optional[tuple[int, float, float, float]] = None

    @property
    def bus_error(self) -> bool:
        """The bus is failing: bus-off or a failing bus object (from ``health``, or set by a node shell)."""
        return self._external_bus_error or self.health.fault

    @bus_error.setter
    def bus_error(self, value: bool) -> None:
        self._external_bus_error = bool(value)

    def on_command(self, command: Command, t: float) -> None:
        self.guard.receive(command, t)

    def _due(self, name: str, t: float, period: float) -> bool:
        if t + 1e-9 < self._next[name]:
            return False
        self._next[name] = max(self._next[name] + period, t)
        return True

    def heartbeat_state(self) -> str:
        return "fault" if self.bus_error else "safe_state" if self.guard.timed_out else "commanding"

    def tick(self, t: float) -> list[can.Message]:
        frames: list[can.Message] = []
        if self._due("command", t, COMMAND_PERIOD):
            out = self.guard.output(t)
            frames.append(self.codec.encode("CMD_STEER", {"SteerAngleCmd": out.steering_angle,
                                                          "SteerRateCmd": out.steering_rate}, t))
            frames.append(self.codec.encode("CMD_TORQUE", {"TorqueRL": out.torque_rl, "TorqueRR": out.torque_rr}, t))
        if self._due("status", t, STATUS_PERIOD):
            self._alive = (self._alive + 1) & 0xFF
            frames.append(self.codec.encode("BRIDGE_HEARTBEAT", {
                "Alive": self._alive, "State": HEARTBEAT_STATE[self.heartbeat_state()]}, t))
            s, h = self.codec.stats, self.health
            frames.append(self.codec.encode("BRIDGE_STATUS", {
                "CommandTimeout": int(self.guard.timed_out), "LimitClamp": int(self.guard.clamped),
                "BusError": int(h.report() or self._external_bus_error),
                "InvalidCommand": int(self.guard.pop_invalid()),
                "BusState": min(int(h.state), int(BusState.BUS_OFF)),
                "ErrorFrames": min(s.error_frames, 255), "BadCounter": min(s.bad_counter, 65535),
                "BadChecksum": min(s.bad_checksum, 65535),
                "BadFrame": min(s.unknown_id + s.bad_length + s.undecodable + s.out_of_range, 65535),
            }, t))
        return frames

    def on_frame(self, frame: can.Message, t: float) -> Optional[Sample]:
        if frame.is_error_frame:
            self.health.on_error_frame(frame, t)
        decoded = self.codec.decode(frame)
        if decoded is None:
            return None
        self.health.on_traffic(t)
        name, v = decoded
        if name == "IMU":
            return ImuSample(t, v["AccelX"], v["AccelY"], v["YawRate"])
        if name == "WHEEL_SPEEDS":
            return WheelSpeedSample(t, v["OmegaRL"], v["OmegaRR"])
        if name == "EPS_STATUS":
            self.guard.observe_angle(v["SteerAngle"], t)
            return EpsSample(t, v["SteerAngle"])
        if name == "GPS_POSITION":
            self._gps_position = (int(v["Counter"]), t, v["PosX"], v["PosY"])
            return None
        if name == "GPS_VELOCITY" and self._gps_position is not None:
            counter, t_position, x, y = self._gps_position
            self._gps_position = None
            if counter == int(v["Counter"]) and abs(t - t_position) <= STATUS_PERIOD:
                return GpsSample(t, t - v["FixAge"], x, y, v["VelX"], v["VelY"])
        return None
