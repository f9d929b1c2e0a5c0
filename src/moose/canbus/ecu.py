"""Vehicle-side ECU emulator core: the car's end of the DBC around the plant.

It validates command frames like a real ECU (counter, CRC, length), applies its own
command timeout (zero torque, steering rate zero), turns commands into the plant input
[δ̇_cmd, T_rl, T_rr] and encodes the sensor samples as frames.
"""
from __future__ import annotations

import math
from typing import Optional

import can
import numpy as np

from moose.signals import EpsSample, GpsSample, ImuSample, WheelSpeedSample

from .codec import Codec


class VehicleEcu:
    def __init__(self, timeout: float = 0.05, codec: Optional[Codec] = None) -> None:
        self.codec = codec or Codec()
        self.timeout = timeout
        self._steer = (-math.inf, 0.0)
        self._torque = (-math.inf, 0.0, 0.0)

    def on_frame(self, frame: can.Message, t: float) -> None:
        decoded = self.codec.decode(frame)
        if decoded is None:
            return
        name, v = decoded
        if name == "CMD_STEER":
            self._steer = (t, v["SteerRateCmd"])
        elif name == "CMD_TORQUE":
            self._torque = (t, v["TorqueRL"], v["TorqueRR"])

    def plant_input(self, t: float) -> np.ndarray:
        rate = self._steer[1] if t - self._steer[0] <= self.timeout else 0.0
        fresh = t - self._torque[0] <= self.timeout
        return np.array([rate, self._torque[1] if fresh else 0.0, self._torque[2] if fresh else 0.0])

    def encode(self, sample: object, t: float) -> list[can.Message]:
        c = self.codec
        if isinstance(sample, ImuSample):
            return [c.encode("IMU", {"YawRate": sample.yaw_rate, "AccelX": sample.ax, "AccelY": sample.ay}, t)]
        if isinstance(sample, WheelSpeedSample):
            return [c.encode("WHEEL_SPEEDS", {"OmegaRL": sample.omega_rl, "OmegaRR": sample.omega_rr}, t)]
        if isinstance(sample, EpsSample):
            return [c.encode("EPS_STATUS", {"SteerAngle": sample.delta}, t)]
        if isinstance(sample, GpsSample):
            return [c.encode("GPS_POSITION", {"PosX": sample.x, "PosY": sample.y}, t),
                    c.encode("GPS_VELOCITY", {"VelX": sample.vX, "VelY": sample.vY, "FixAge": sample.t - sample.t_measured}, t)]
        raise TypeError(f"sample = {sample!r} has no frame")
