"""Vehicle-side ECU emulator core: the car's end of config/kanon.dbc around the plant.

It validates command frames like a real ECU (length, CRC keyed with the identifier, rolling
counter, signal ranges) and turns the commands into the plant input U = [δ̇_cmd, T_rl, T_rr]
(``moose.vehicle``).  Sensor samples (``moose.sensors``, which samples at the DBC's cycle
times: IMU, wheel speeds and EPS at 100 Hz, GPS at 1 Hz) leave as frames; values beyond a
signal's range saturate at full scale, as a sensor does.

Its command timeout has two levels:

1. a command frame older than ``timeout`` is not applied: the inverters give zero torque and
   the EPS stops (rate 0);
2. with a ``maneuver`` (:class:`moose.minimum_risk.MinimumRiskManeuver`), an ECU that has been
   commanded and then loses either command stream runs the stack's minimum-risk maneuver
   itself, from its own measurements (the EPS angle, the rear wheel speeds it sends): steer
   back to straight, brake with the rear motors, hold still.  Fresh commands on both streams
   end it.  Without level 2 a car whose bridge dies coasts on an arc at the held steering
   angle; docs/graph.md ("Fault matrix") states level 2 as a requirement on the car's ECUs.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Optional

import can
import numpy as np

from moose.minimum_risk import Command, MinimumRiskManeuver
from moose.signals import EpsSample, GpsSample, ImuSample, WheelSpeedSample

from .codec import Codec

ECU_TIMEOUT = 0.05
"""Command timeout of the vehicle's ECUs (s): five 10 ms command cycles."""


class VehicleEcu:
    """Commands in, plant input out; sensor samples in, frames out."""

    def __init__(self, timeout: float = ECU_TIMEOUT, codec: Optional[Codec] = None,
                 maneuver: Optional[MinimumRiskManeuver] = None) -> None:
        if isinstance(timeout, bool) or not (isinstance(timeout, (int, float)) and 0.0 < timeout < math.inf):
            raise ValueError(f"timeout = {timeout!r} is invalid: expected a positive number of seconds")
        self.codec = codec or Codec(node="VEHICLE")
        self.timeout = float(timeout)
        self.maneuver = maneuver
        """Level 2 of the timeout (module docstring); ``None``: an ECU that only stops applying commands.
        :meth:`plant_input` runs one step of it per call, so call that once per ``maneuver.period``."""
        self._steer = (-math.inf, 0.0)
        self._torque = (-math.inf, 0.0, 0.0)
        self.commanded = False
        """A valid command frame has arrived (the stack had the car): level 2 is armed."""
        self.commands_lost = False
        """At the last plant input the ECU had been commanded and either command stream was stale: the stack
        no longer controlled the car (level 1 or 2 applied)."""
        self.minimum_risk = False
        """The last plant input was the ECU's own minimum-risk maneuver."""
        self._angle = (-math.inf, 0.0)
        self._wheel_speed = (-math.inf, 0.0)
        self._out = Command(0.0, 0.0, 0.0, 0.0)
        """The last plant input as a command (the maneuver starts from its torques)."""
        self.unsendable = 0
        """Sensor samples with a non-finite value (not sent)."""

    def on_frame(self, frame: can.Message, t: float) -> None:
        decoded = self.codec.decode(frame)
        if decoded is None:
            return
        name, v = decoded
        if name == "CMD_STEER":
            self._steer = (t, v["SteerRateCmd"])
            self.commanded = True
        elif name == "CMD_TORQUE":
            self._torque = (t, v["TorqueRL"], v["TorqueRR"])
            self.commanded = True

    def steering_alive(self, t: float) -> bool:
        return t - self._steer[0] <= self.timeout + 1e-9

    def torque_alive(self, t: float) -> bool:
        return t - self._torque[0] <= self.timeout + 1e-9

    def plant_input(self, t: float) -> np.ndarray:
        """U = [δ̇_cmd, T_rl, T_rr] at ``t``: level 1, zero rate / zero torque for a command older than the
        timeout; level 2, the minimum-risk maneuver once commanded and either command is stale."""
        steering, torque = self.steering_alive(t), self.torque_alive(t)
        angle = self._measured(self._angle, t)
        self.commands_lost = self.commanded and not (steering and torque)
        if self.maneuver is not None and self.commands_lost:
            if not self.minimum_risk:
                self.maneuver.reset()
                self.minimum_risk = True
                self._out = dataclasses.replace(self._out, steering_angle=0.0 if angle is None else angle)
            self._out = self.maneuver.step(self._out, angle, self._measured(self._wheel_speed, t))
        else:
            self.minimum_risk = False  # the angle reference is taken from the EPS when the maneuver starts
            self._out = Command(0.0, self._steer[1] if steering else 0.0, self._torque[1] if torque else 0.0,
                                self._torque[2] if torque else 0.0)
        return np.array([self._out.steering_rate, self._out.torque_rl, self._out.torque_rr])

    def _measured(self, sample: tuple[float, float], t: float) -> Optional[float]:
        """The ECU's own measurement, if it is not older than the timeout."""
        return sample[1] if t - sample[0] <= self.timeout + 1e-9 else None

    def encode(self, sample: object, t: float) -> list[can.Message]:
        """The frames of one sensor sample (GPS: position and velocity, same counter).  The EPS angle and the
        wheel speeds are also the ECU's own measurements (level 2 of the timeout)."""
        c = self.codec
        if isinstance(sample, EpsSample) and math.isfinite(sample.delta):
            self._angle = (t, sample.delta)
        elif (isinstance(sample, WheelSpeedSample) and math.isfinite(sample.omega_rl)
              and math.isfinite(sample.omega_rr)):
            self._wheel_speed = (t, 0.5 * (sample.omega_rl + sample.omega_rr))
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
