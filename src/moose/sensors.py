"""Simulated sensors of the FPEV2-Kanon (Sec. V): IMU, GPS (1 Hz, lagged), wheel speeds, EPS angle.

Each sensor samples the true plant state on its own schedule and adds
zero-mean Gaussian noise from one seeded generator, so a run is reproducible.
The GPS fix taken at ``t_measured`` reaches the observer ``gps_lag_s`` later
(the paper's "communication delays in reading the GPS signal").  Default noise
levels are those of an automotive MEMS IMU, an RTK receiver and encoder-based
wheel and steering sensors (docs/design.md).
"""
from __future__ import annotations

import dataclasses
from collections import deque
from typing import Union

import numpy as np

from .params import VehicleParams, check, non_negative, positive
from .signals import EpsSample, GpsSample, ImuSample, WheelSpeedSample
from .vehicle import DELTA, GAMMA, OMEGA_RL, OMEGA_RR, THETA, VX, VY, X, Y

Sample = Union[ImuSample, GpsSample, WheelSpeedSample, EpsSample]


@dataclasses.dataclass(frozen=True)
class SensorParams:
    """Rates (Hz), GPS lag (s) and noise standard deviations (SI units)."""

    imu_rate_hz: float = 100.0
    wheel_rate_hz: float = 100.0
    eps_rate_hz: float = 100.0
    gps_rate_hz: float = 1.0
    gps_lag_s: float = 0.2
    accel_std: float = 0.05
    gyro_std: float = 0.002
    wheel_std: float = 0.05
    eps_std: float = 0.001
    gps_pos_std: float = 0.02
    gps_vel_std: float = 0.03

    def __post_init__(self) -> None:
        for name in ("imu_rate_hz", "wheel_rate_hz", "eps_rate_hz", "gps_rate_hz"):
            check(name, getattr(self, name), positive, "a positive rate (Hz)")
        for name in ("gps_lag_s", "accel_std", "gyro_std", "wheel_std", "eps_std", "gps_pos_std", "gps_vel_std"):
            check(name, getattr(self, name), non_negative, "a non-negative number")


class Sensors:
    """All sensors of the car; :meth:`sample` returns what is delivered at time ``t``."""

    def __init__(self, params: SensorParams, vehicle: VehicleParams, rng: np.random.Generator) -> None:
        self.params = params
        self.vehicle = vehicle
        self.rng = rng
        self._next = {"imu": 0.0, "wheel": 0.0, "eps": 0.0, "gps": 0.0}
        self._pending: deque[GpsSample] = deque()

    def _due(self, name: str, t: float, rate: float) -> bool:
        if t + 1e-9 < self._next[name]:
            return False
        self._next[name] += 1.0 / rate
        return True

    def sample(self, t: float, state: np.ndarray, specific_force: tuple[float, float]) -> list[Sample]:
        p, n = self.params, self.rng.normal
        out: list[Sample] = []
        if self._due("imu", t, p.imu_rate_hz):
            e = n(0.0, 1.0, 3)
            out.append(ImuSample(t, specific_force[0] + p.accel_std * e[0], specific_force[1] + p.accel_std * e[1],
                                 float(state[GAMMA] + p.gyro_std * e[2])))
        if self._due("wheel", t, p.wheel_rate_hz):
            e = n(0.0, p.wheel_std, 2)
            out.append(WheelSpeedSample(t, float(state[OMEGA_RL] + e[0]), float(state[OMEGA_RR] + e[1])))
        if self._due("eps", t, p.eps_rate_hz):
            out.append(EpsSample(t, float(state[DELTA] + n(0.0, p.eps_std))))
        if self._due("gps", t, p.gps_rate_hz):
            c, s = np.cos(state[THETA]), np.sin(state[THETA])
            vX = state[VX] * c - state[VY] * s
            vY = state[VX] * s + state[VY] * c
            self._pending.append(GpsSample(
                t + p.gps_lag_s, t, state[X] + n(0.0, p.gps_pos_std), state[Y] + n(0.0, p.gps_pos_std),
                vX + n(0.0, p.gps_vel_std), vY + n(0.0, p.gps_vel_std)))
        while self._pending and self._pending[0].t <= t + 1e-9:
            fix = self._pending.popleft()
            out.append(dataclasses.replace(fix, t=t))
        return out
