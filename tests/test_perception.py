"""Sensors, state observer and obstacle detector on the real plant."""
from __future__ import annotations

import math

import numpy as np
import pytest

from moose.detector import ObstacleDetector
from moose.maneuver import MaxSteeringTable, lateral_steering_index
from moose.observer import StateObserver
from moose.params import VehicleParams
from moose.schema import DetectorParams, ManeuverParams, ObserverParams, SensorParams
from moose.sensors import Sensors
from moose.signals import EpsSample, GpsSample, ImuSample, Obstacle, StateEstimate, WheelSpeedSample
from moose.vehicle import DELTA, VehiclePlant, initial_state

P = VehicleParams()
OBSERVER = ObserverParams()


def double_lane_change(seed: int, observer_params: ObserverParams = OBSERVER, seconds: float = 8.0):
    plant = VehiclePlant(P)
    plant.reset(initial_state(P, vx=7.0))
    sensors = Sensors(SensorParams(), P, np.random.default_rng(seed))
    s0 = plant.state
    observer = StateObserver(observer_params, P, StateEstimate(0.0, s0[0], s0[1], 0.0, 6.0, 0.0, 0.0, 0.0))
    truth, est, samples = [], [], []
    u = np.zeros(3)
    for k in range(int(seconds * 100)):
        t = k * 0.01
        state = plant.state
        for sample in sensors.sample(t, state, plant.imu_specific_force(state, u)):
            samples.append(sample)
            observer.update(sample)
        e = observer.estimate()
        truth.append(state.copy())
        est.append([e.x, e.y, e.theta, e.vx, e.vy, e.gamma, e.beta])
        target = 0.12 * math.sin(2 * math.pi * t / 2.5) if 1.0 < t < 6.0 else 0.0
        u = np.array([20.0 * (target - state[DELTA]), 15.0, 15.0])
        plant.step(u, 10)
    return np.array(truth), np.array(est), samples


def test_sensor_rates_lag_and_determinism() -> None:
    _, _, samples = double_lane_change(1, seconds=3.0)
    count = {kind: sum(isinstance(s, kind) for s in samples)
             for kind in (ImuSample, GpsSample, WheelSpeedSample, EpsSample)}
    assert count[ImuSample] == count[WheelSpeedSample] == count[EpsSample] == 300
    assert count[GpsSample] == 3  # fixes measured at 0, 1, 2 s, delivered 0.2 s later
    for fix in (s for s in samples if isinstance(s, GpsSample)):
        assert fix.t - fix.t_measured == pytest.approx(0.2)
    _, _, again = double_lane_change(1, seconds=3.0)
    assert samples == again


def test_observer_tracks_sideslip_and_velocities() -> None:
    truth, est, _ = double_lane_change(2)
    beta = np.arctan2(truth[:, 4], truth[:, 3])
    settled = slice(100, None)
    rms = lambda a: float(np.sqrt(np.mean(np.square(a[settled]))))  # noqa: E731
    assert rms(est[:, 6] - beta) < 0.01
    assert rms(est[:, 4] - truth[:, 4]) < 0.06
    assert rms(est[:, 5] - truth[:, 5]) < 0.01
    assert rms(est[:, 3] - truth[:, 3]) < 0.1  # converged from a 1 m/s initial error
    assert np.max(np.abs(est[settled, 2] - truth[settled, 2])) < 0.03
    assert rms(np.hypot(est[:, 0] - truth[:, 0], est[:, 1] - truth[:, 1])) < 0.3


def test_lag_compensation_beats_fusing_late_fixes_as_current() -> None:
    truth, compensated, _ = double_lane_change(3)
    _, naive, _ = double_lane_change(3, ObserverParams(history_s=0.01))
    err = lambda e: float(np.sqrt(np.mean((e[:, 0] - truth[:, 0]) ** 2 + (e[:, 1] - truth[:, 1]) ** 2)))  # noqa: E731
    assert err(compensated) < 0.7 * err(naive)


def test_observer_refuses_out_of_order_samples_and_is_finite_at_rest() -> None:
    observer = StateObserver(ObserverParams(), P)
    observer.update(ImuSample(1.0, 0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="sample.t = 0.5"):
        observer.update(ImuSample(0.5, 0.0, 0.0, 0.0))
    for k in range(100):
        observer.update(ImuSample(1.0 + 0.01 * k, 0.0, 0.0, 0.0))
        observer.update(WheelSpeedSample(1.0 + 0.01 * k, 0.0, 0.0))
    e = observer.estimate()
    assert all(math.isfinite(v) for v in (e.x, e.y, e.vx, e.vy, e.beta)) and abs(e.vx) < 0.05


@pytest.fixture(scope="module")
def table() -> MaxSteeringTable:
    return MaxSteeringTable.build(P, ManeuverParams())


def test_detector_measures(table: MaxSteeringTable) -> None:
    detector = ObstacleDetector(DetectorParams(), table)
    zone = Obstacle(9.0, 11.0, -2.0, 2.0)
    est = StateEstimate(0.0, -0.8, 0.05, 0.0, 7.0, 0.0, 0.0, 0.0)
    threat = detector.update(0.0, est, [zone])
    assert threat is not None
    assert threat.tau == pytest.approx(9.8 / 7.0)
    assert threat.side == 1 and threat.w == pytest.approx(1.95)  # near-tie goes left; far edge from the path
    assert threat.nu == pytest.approx(lateral_steering_index(1.95, 1.4, 7.0, table))
    # moving aside does not change w (the path is latched); passing clears the threat
    moved = detector.update(0.5, StateEstimate(0.5, 3.0, 1.5, 0.0, 7.0, 0.0, 0.0, 0.0), [zone])
    assert moved is not None and moved.w == pytest.approx(1.95)
    assert detector.update(1.0, StateEstimate(1.0, 13.5, 3.0, 0.0, 7.0, 0.0, 0.0, 0.0), [zone]) is None
    assert detector.update(1.0, est, []) is None


def test_detector_picks_the_cheaper_side(table: MaxSteeringTable) -> None:
    detector = ObstacleDetector(DetectorParams(), table)
    threat = detector.update(0.0, StateEstimate(0.0, 0.0, 0.0, 0.0, 6.0, 0.0, 0.0, 0.0),
                             [Obstacle(20.0, 22.0, -0.5, 3.0)])
    assert threat is not None and threat.side == -1 and threat.w == pytest.approx(0.5)
