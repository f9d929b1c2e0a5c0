"""Vehicle-side ECU emulator core: the car's end of config/kanon.dbc around the plant.

It validates command frames like a real ECU (length, CRC keyed with the identifier, rolling
counter, signal ranges), applies its own command timeout — the inverters set zero torque
and the EPS stops (rate 0) when their command frame is older than ``timeout`` — and turns
the commands into the plant input U = [δ̇_cmd, T_rl, T_rr] (``moose.vehicle``).  Sensor
samples (``moose.sensors``, which samples at the DBC's cycle times: IMU, wheel speeds and
EPS at 100 Hz, GPS at 1 Hz) leave as frames; values beyond a signal's range saturate at
full scale, as a sensor does.
"""
from __future__ import annotations

import math
from typing import Optional

import can
import numpy as np

from moose.signals import EpsSample, GpsSample, ImuSample, WheelSpeedSample

from .codec import Codec

ECU_TIMEOUT = 0.05
"""Command timeout of the vehicle's ECUs (s): five 10 ms command cycles."""


class VehicleEcu:
    """Commands in, plant input out; sensor samples in, frames out."""

    def __init__(self, timeout: float = ECU_TIMEOUT, codec: Optional[Codec] = None) -> None:
        if isinstance(timeout, bool) or not (isinstance(timeout, (int, float)) and 0.0 < timeout < math.inf):
            raise ValueError(f"timeout = {timeout!r} is invalid: expected a positive number of seconds")
        self.codec = codec or Codec(node="VEHICLE")
        self.timeout = float(timeout)
        self._steer = (-math.inf, 0.0)
        self._torque = (-math.inf, 0.0, 0.0)
        self.unsendable = 0
        """Sensor samples with a non-finite value (not sent)."""

    def on_frame(self, frame: can.Message, t: float) -> None:
        decoded = self.codec.decode(frame)
        if decoded is None:
            return
        name, v = decoded
        if name == "CMD_STEER":
            self._steer = (t, v["SteerRateCmd"])
        elif name == "CMD_TORQUE":
            self._torque = (t, v["TorqueRL"], v["TorqueRR"])

    def steering_alive(self, t: float) -> bool:
        return t - self._steer[0] <= self.timeout + 1e-9

    def torque_alive(self, t: float) -> bool:
        return t - self._torque[0] <= self.timeout + 1e-9

    def plant_input(self, t: float) -> np.ndarray:
        """U = [δ̇_cmd, T_rl, T_rr] at ``t``: zero rate / zero torque for a command older than the timeout."""
        rate = self._steer[1] if self.steering_alive(t) else 0.0
        fresh = self.torque_alive(t)
        return np.array([rate, self._torque[1] if fresh else 0.0, self._torque[2] if fresh else 0.0])

    def encode(self, sample: object, t: float) -> list[can.Message]:
        """The frames of one sensor sample (GPS: position and velocity, same counter)."""
        c = self.codec
        try:
            if isinstance(sample, ImuSample):
                return [c.encode("IMU", {"YawRate": sample.yaw_rate, "AccelX": sample.ax, "AccelY": sample.ay}, t,
                                 saturate=True)]
            if isinstance(sample, WheelSpeedSample):
                return [c.encode("WHEEL_SPEEDS", {"OmegaRL": sample.omega_rl, "OmegaRR": sample.omega_rr}, t,
                                 saturate=True)]
            if isinstance(sample, EpsSample):
                return [c.encode("EPS_STATUS", {"SteerAngle": sample.delta}, t, saturate=True)]
            if isinstance(sample, GpsSample):
                if not all(math.isfinite(v) for v in (sample.x, sample.y, sample.vX, sample.vY, sample.t_measured)):
                    self.unsendable += 1  # checked before the position frame, so no half of a fix goes out
                    return []
                return [c.encode("GPS_POSITION", {"PosX": sample.x, "PosY": sample.y}, t, saturate=True),
                        c.encode("GPS_VELOCITY", {"VelX": sample.vX, "VelY": sample.vY,
                                                  "FixAge": sample.t - sample.t_measured}, t, saturate=True)]
        except ValueError:
            self.unsendable += 1
            return []
        raise TypeError(f"sample = {sample!r} has no frame")

    def frames(self, samples: list, t: float) -> list[can.Message]:
        """The frames of all ``samples`` delivered at ``t``."""
        return [frame for sample in samples for frame in self.encode(sample, t)]
