"""Simulated sensors of the FPEV2-Kanon (Sec. V): IMU, GPS (1 Hz, lagged), wheel speeds, EPS angle.

Each sensor samples the true plant state on its own schedule (sample k of a
sensor at rate f is due at t = k / f) and adds zero-mean Gaussian noise from
one seeded generator, so a run is reproducible for a seed.  The GPS fix taken
at ``t_measured`` reaches the observer ``gps_lag_s`` later (the paper's
"communication delays in reading the GPS signal"; Sec. V: GPS at 1 Hz) through
a delay buffer.

Default noise (1σ), per sample:

* accelerometer 0.05 m/s² — automotive MEMS IMUs have a noise density of
  100–300 µg/√Hz (≈ 0.01–0.03 m/s² over a 50 Hz bandwidth); the margin stands
  for chassis vibration;
* gyro 0.002 rad/s (0.11 °/s) — 0.01–0.02 °/s/√Hz over 50 Hz;
* wheel speed 0.05 rad/s (0.015 m/s at the tread) — the filtered speed
  signal of an in-wheel motor's resolver-based inverter;
* EPS angle 0.001 rad — a 12-bit absolute steering-column encoder behind the
  rack ratio;
* GPS position 0.02 m and velocity 0.03 m/s — RTK fixed solution (the paper's
  car drives a campus field with an RTK receiver; a plain GNSS fix of ~2 m
  would make a 0.5 m lateral margin meaningless).

Biases and scale errors are not modelled (the paper gives none).
"""
from __future__ import annotations

import dataclasses
import math
from collections import deque

import numpy as np

from .params import VehicleParams
from .schema import SensorParams
from .signals import EpsSample, GpsSample, ImuSample, Sample, WheelSpeedSample
from .state import DELTA, GAMMA, OMEGA_RL, OMEGA_RR, THETA, VX, VY, X, Y

_TICK_TOLERANCE = 1e-6
"""Fraction of a sample period by which a call may precede a sample's due time (float round-off of k · dt)."""


class Sensors:
    """All sensors of the car; :meth:`sample` returns what is delivered at time ``t``.

    Call it at least as often as the fastest sensor (the closed loop calls it at
    every motion tick); a sensor whose samples fall between two calls delivers
    one sample at the later call (no bursts of stale samples).
    """

    def __init__(self, params: SensorParams, vehicle: VehicleParams, rng: np.random.Generator) -> None:
        self.params = params
        self.vehicle = vehicle
        self.rng = rng
        self._rates = (params.imu_rate_hz, params.wheel_rate_hz, params.eps_rate_hz, params.gps_rate_hz)
        """Rates of the IMU, the wheel speeds, the EPS and the GPS (Hz), in the order of :meth:`_due`."""
        self._last = [-math.inf] * len(self._rates)
        self._pending: deque[GpsSample] = deque()

    def _due(self, t: float) -> list[bool]:
        """Per sensor (IMU, wheel speeds, EPS, GPS): True once per sample index k = ⌊t f⌋."""
        last = self._last
        due = []
        for i, rate in enumerate(self._rates):
            index = math.floor(t * rate + _TICK_TOLERANCE)
            fresh = index > last[i]
            if fresh:
                last[i] = index
            due.append(fresh)
        return due

    def sample(self, t: float, state: np.ndarray, specific_force: tuple[float, float]) -> list[Sample]:
        """Samples delivered at ``t`` from the true ``state`` and the IMU ``specific_force`` (a_x, a_y)."""
        p, n = self.params, self.rng.normal
        out: list[Sample] = []
        imu, wheel, eps, gps = self._due(t)
        if imu and wheel and eps:
            # the usual tick: the same six draws, in the same order, as the three calls below (a
            # Generator's normal(0, s) is s times its next standard normal), in one call
            z = self.rng.standard_normal(6).tolist()
            true = state.tolist()  # Python floats: the same sums as with NumPy's scalars, made faster
            a_x, a_y = specific_force
            out.append(ImuSample(t, float(a_x) + p.accel_std * z[0], float(a_y) + p.accel_std * z[1],
                                 true[GAMMA] + p.gyro_std * z[2]))
            out.append(WheelSpeedSample(t, true[OMEGA_RL] + p.wheel_std * z[3], true[OMEGA_RR] + p.wheel_std * z[4]))
            out.append(EpsSample(t, true[DELTA] + p.eps_std * z[5]))
        else:
            if imu:
                e = n(0.0, 1.0, 3)
                out.append(ImuSample(t, float(specific_force[0] + p.accel_std * e[0]),
                                     float(specific_force[1] + p.accel_std * e[1]),
                                     float(state[GAMMA] + p.gyro_std * e[2])))
            if wheel:
                e = n(0.0, p.wheel_std, 2)
                out.append(WheelSpeedSample(t, float(state[OMEGA_RL] + e[0]), float(state[OMEGA_RR] + e[1])))
            if eps:
                out.append(EpsSample(t, float(state[DELTA] + n(0.0, p.eps_std))))
        if gps:
            c, s = math.cos(state[THETA]), math.sin(state[THETA])
            vX = state[VX] * c - state[VY] * s
            vY = state[VX] * s + state[VY] * c
            self._pending.append(GpsSample(
                t + p.gps_lag_s, t, float(state[X] + n(0.0, p.gps_pos_std)), float(state[Y] + n(0.0, p.gps_pos_std)),
                float(vX + n(0.0, p.gps_vel_std)), float(vY + n(0.0, p.gps_vel_std))))
        while self._pending and self._pending[0].t <= t + 1e-9:
            fix = self._pending.popleft()
            out.append(dataclasses.replace(fix, t=t))
        return out
