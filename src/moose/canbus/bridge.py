"""Bridge core: actuator commands → guarded command frames; vehicle frames → sensor samples.

Pure logic, time passed in.  ``on_command`` takes the motion controller's command;
``tick(t)`` returns the frames due at t (commands every 10 ms through the
:class:`~moose.canbus.safety.CommandGuard`, heartbeat and status every 100 ms);
``on_frame`` validates a received frame and returns the core's sample record, or
``None`` for a dropped frame (counted in ``codec.stats``) — it never raises.
"""
from __future__ import annotations

from typing import Optional, Union

import can

from moose.signals import EpsSample, GpsSample, ImuSample, WheelSpeedSample

from .codec import Codec
from .safety import Command, CommandGuard, GuardParams

Sample = Union[ImuSample, GpsSample, WheelSpeedSample, EpsSample]


class BridgeCore:
    def __init__(self, guard: GuardParams = GuardParams(), codec: Optional[Codec] = None) -> None:
        self.codec = codec or Codec()
        self.guard = CommandGuard(guard)
        self.bus_error = False
        self._next = {"command": 0.0, "status": 0.0}
        self._alive = 0
        self._gps_position: Optional[tuple[float, float, float]] = None

    def on_command(self, command: Command, t: float) -> None:
        self.guard.receive(command, t)

    def _due(self, name: str, t: float, period: float) -> bool:
        if t + 1e-9 < self._next[name]:
            return False
        self._next[name] = max(self._next[name] + period, t)
        return True

    def tick(self, t: float) -> list[can.Message]:
        frames: list[can.Message] = []
        if self._due("command", t, 0.01):
            out = self.guard.output(t)
            frames.append(self.codec.encode("CMD_STEER", {"SteerAngleCmd": out.steering_angle,
                                                          "SteerRateCmd": out.steering_rate}, t))
            frames.append(self.codec.encode("CMD_TORQUE", {"TorqueRL": out.torque_rl, "TorqueRR": out.torque_rr}, t))
        if self._due("status", t, 0.1):
            self._alive = (self._alive + 1) & 0xFF
            state = 2 if self.bus_error else 1 if self.guard.timed_out else 0
            frames.append(self.codec.encode("BRIDGE_HEARTBEAT", {"Alive": self._alive, "State": state}, t))
            s = self.codec.stats
            frames.append(self.codec.encode("BRIDGE_STATUS", {
                "CommandTimeout": int(self.guard.timed_out), "LimitClamp": int(self.guard.clamped),
                "BusError": int(self.bus_error), "BadCounter": min(s.bad_counter, 65535),
                "BadChecksum": min(s.bad_checksum, 65535), "UnknownOrBadLength": min(s.unknown_id + s.bad_length, 65535),
            }, t))
        return frames

    def on_frame(self, frame: can.Message, t: float) -> Optional[Sample]:
        decoded = self.codec.decode(frame)
        if decoded is None:
            return None
        name, v = decoded
        if name == "IMU":
            return ImuSample(t, v["AccelX"], v["AccelY"], v["YawRate"])
        if name == "WHEEL_SPEEDS":
            return WheelSpeedSample(t, v["OmegaRL"], v["OmegaRR"])
        if name == "EPS_STATUS":
            return EpsSample(t, v["SteerAngle"])
        if name == "GPS_POSITION":
            self._gps_position = (t, v["PosX"], v["PosY"])
            return None
        if name == "GPS_VELOCITY" and self._gps_position is not None and abs(self._gps_position[0] - t) < 0.05:
            _, x, y = self._gps_position
            self._gps_position = None
            return GpsSample(t, t - v["FixAge"], x, y, v["VelX"], v["VelY"])
        return None
