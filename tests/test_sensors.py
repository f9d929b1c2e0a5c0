"""Sensors: schedules, GPS lag through the delay buffer, noise statistics, determinism."""
from __future__ import annotations

import math

import numpy as np
import pytest

from moose.params import ParamError, VehicleParams
from moose.schema import SensorParams
from moose.sensors import Sensors
from moose.signals import EpsSample, GpsSample, ImuSample, WheelSpeedSample
from moose.vehicle import DELTA, GAMMA, OMEGA_RL, OMEGA_RR, THETA, VX, VY, X, Y

P = VehicleParams()


def true_state(t: float) -> np.ndarray:
    """A state that changes with time, so a sample can be matched to the instant it describes."""
    state = np.zeros(9)
    state[[X, Y, THETA, VX, VY, GAMMA, OMEGA_RL, OMEGA_RR, DELTA]] = (
        5.0 * t, 0.3 * t**2, 0.1 * t, 5.0, 0.2, 0.1, 5.0 / P.r + t, 5.0 / P.r - t, 0.01 * t)
    return state


def collect(params: SensorParams, seconds: float, seed: int = 0, dt: float = 1e-3, t0: float = 0.0):
    sensors = Sensors(params, P, np.random.default_rng(seed))
    out = []
    for k in range(int(round(seconds / dt))):
        t = t0 + k * dt
        out.extend(sensors.sample(t, true_state(t), (0.5 + t, -1.0)))
    return out


def of(kind: type, samples: list) -> list:
    return [s for s in samples if isinstance(s, kind)]


def test_each_sensor_on_its_own_rate() -> None:
    params = SensorParams(imu_rate_hz=100.0, wheel_rate_hz=50.0, eps_rate_hz=200.0, gps_rate_hz=1.0)
    samples = collect(params, 10.0)
    for kind, rate in ((ImuSample, 100.0), (WheelSpeedSample, 50.0), (EpsSample, 200.0)):
        times = np.array([s.t for s in of(kind, samples)])
        assert len(times) == int(10.0 * rate)
        assert np.diff(times) == pytest.approx(1.0 / rate, abs=1e-9)
    fixes = of(GpsSample, samples)
    assert [f.t_measured for f in fixes] == pytest.approx(np.arange(10.0))


def test_coarse_calls_deliver_one_sample_per_call_not_bursts() -> None:
    samples = collect(SensorParams(imu_rate_hz=100.0), 1.0, dt=0.03)
    times = [s.t for s in of(ImuSample, samples)]
    assert len(times) == len(set(times)) == int(round(1.0 / 0.03))
    late = collect(SensorParams(), 2.0, dt=0.01, t0=100.0)  # a clock that does not start at zero
    assert len(of(ImuSample, late)) == 200
    assert [f.t_measured for f in of(GpsSample, late)] == pytest.approx([100.0, 101.0])


@pytest.mark.parametrize("lag", [0.2, 0.35, 0.0])
def test_gps_is_delivered_lag_seconds_after_the_fix_and_describes_that_instant(lag: float) -> None:
    params = SensorParams(gps_lag_s=lag, gps_pos_std=0.0, gps_vel_std=0.0)
    fixes = of(GpsSample, collect(params, 5.0))
    assert len(fixes) == 5
    for fix in fixes:
        assert fix.t - fix.t_measured == pytest.approx(lag, abs=1.5e-3)
        s = true_state(fix.t_measured)
        assert (fix.x, fix.y) == pytest.approx((s[X], s[Y]), abs=1e-12)
        # global velocity: body velocity rotated by the yaw angle
        c, si = math.cos(s[THETA]), math.sin(s[THETA])
        assert fix.vX == pytest.approx(s[VX] * c - s[VY] * si, abs=1e-12)
        assert fix.vY == pytest.approx(s[VX] * si + s[VY] * c, abs=1e-12)
        assert fix.t_measured == 0.0 or fix.vY > 0.2  # the rotation matters at theta > 0


def test_noise_is_zero_mean_with_the_configured_deviation() -> None:
    params = SensorParams(accel_std=0.1, gyro_std=0.01, wheel_std=0.2, eps_std=0.003, gps_pos_std=0.5,
                          gps_vel_std=0.4, gps_rate_hz=100.0, gps_lag_s=0.0)
    samples = collect(params, 20.0, dt=0.01)
    errors = {
        "ax": ([s.ax - (0.5 + s.t) for s in of(ImuSample, samples)], 0.1),
        "ay": ([s.ay + 1.0 for s in of(ImuSample, samples)], 0.1),
        "gyro": ([s.yaw_rate - 0.1 for s in of(ImuSample, samples)], 0.01),
        "wheel": ([s.omega_rl - true_state(s.t)[OMEGA_RL] for s in of(WheelSpeedSample, samples)]
                  + [s.omega_rr - true_state(s.t)[OMEGA_RR] for s in of(WheelSpeedSample, samples)], 0.2),
        "eps": ([s.delta - true_state(s.t)[DELTA] for s in of(EpsSample, samples)], 0.003),
        "gps_x": ([s.x - true_state(s.t_measured)[X] for s in of(GpsSample, samples)], 0.5),
        "gps_vY": ([s.vY - (5.0 * math.sin(0.1 * s.t_measured) + 0.2 * math.cos(0.1 * s.t_measured))
                    for s in of(GpsSample, samples)], 0.4),
    }
    for name, (values, std) in errors.items():
        values = np.asarray(values)
        assert len(values) >= 1990, name
        assert abs(values.mean()) < 4 * std / math.sqrt(len(values)), name
        assert values.std() == pytest.approx(std, rel=0.06), name
    ax, gyro = np.asarray(errors["ax"][0]), np.asarray(errors["gyro"][0])
    assert abs(np.corrcoef(ax, gyro)[0, 1]) < 0.1  # independent channels


def test_deterministic_for_a_seed() -> None:
    a, b = collect(SensorParams(), 3.0, seed=7), collect(SensorParams(), 3.0, seed=7)
    c = collect(SensorParams(), 3.0, seed=8)
    assert a == b
    assert a != c and [type(s) for s in a] == [type(s) for s in c]


def test_noise_free_sensors_read_the_truth() -> None:
    zero = SensorParams(accel_std=0.0, gyro_std=0.0, wheel_std=0.0, eps_std=0.0, gps_pos_std=0.0, gps_vel_std=0.0)
    for s in of(EpsSample, collect(zero, 0.5)):
        assert s.delta == true_state(s.t)[DELTA]


def test_invalid_parameters_are_refused() -> None:
    with pytest.raises(ParamError, match="gps_rate_hz = 0"):
        SensorParams(gps_rate_hz=0.0)
    with pytest.raises(ParamError, match="accel_std = -0.1"):
        SensorParams(accel_std=-0.1)
