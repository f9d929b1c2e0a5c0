"""State observer (Sec. III): the EKF against the real plant and sensors on an evasive maneuver.

Expectations come from outside the filter: the plant's true state, the travel of the car
during the GPS lag (v·lag) for a filter that ignores the lag, the equality of a late fix
replayed from its measurement time with the same fix delivered on time, x = v t for
straight running, and the plant's friction coefficient for the estimated μ.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pytest

from moose.observer import StateObserver
from moose.params import ParamError, VehicleParams, replace
from moose.schema import ObserverParams, SensorParams
from moose.sensors import Sensors
from moose.signals import EpsSample, GpsSample, ImuSample, StateEstimate, WheelSpeedSample
from moose.vehicle import DELTA, GAMMA, THETA, VX, VY, VehiclePlant, X, Y, initial_state

P = VehicleParams(mu=0.5)  # a test drive that excites the lateral dynamics
V0 = 7.0
SENSORS = SensorParams()
LAG = SENSORS.gps_lag_s
OBSERVER = ObserverParams()
DT = 0.01


def steering_target(t: float, amplitude: float = 0.15) -> float:
    """Double lane change: one sine period out (1.0–3.5 s), the mirrored period back (4.0–6.5 s)."""
    if 1.0 < t < 3.5:
        return amplitude * math.sin(2.0 * math.pi * (t - 1.0) / 2.5)
    if 4.0 < t < 6.5:
        return -amplitude * math.sin(2.0 * math.pi * (t - 4.0) / 2.5)
    return 0.0


@dataclasses.dataclass
class Run:
    t: np.ndarray
    truth: np.ndarray
    """(n, 9) plant states."""
    est: np.ndarray
    """(n, 6) estimated [x, y, θ, v_x, v_y, γ]."""
    beta_est: np.ndarray
    samples: list[Any]
    observer: StateObserver

    def rms(self, column: int, start: float = 1.0) -> float:
        keep = self.t >= start
        return float(np.sqrt(np.mean((self.est[keep, column] - self.truth[keep, column]) ** 2)))

    @property
    def beta(self) -> np.ndarray:
        return np.arctan2(self.truth[:, VY], self.truth[:, VX])

    @property
    def position_error(self) -> np.ndarray:
        return np.hypot(self.est[:, 0] - self.truth[:, X], self.est[:, 1] - self.truth[:, Y])


def double_lane_change(seed: int = 11, observer: ObserverParams = OBSERVER,
                       sensors: SensorParams = SENSORS, plant_mu: float = P.mu, model_mu: float = P.mu,
                       vx_initial_estimate: float = 5.5, seconds: float = 8.0) -> Run:
    """Real plant at 7 m/s, δ ≤ 0.15 rad through the EPS loop, 15 N m per rear motor."""
    vehicle = replace(P, mu=plant_mu)
    plant = VehiclePlant(vehicle)
    plant.reset(initial_state(vehicle, vx=V0))
    sens = Sensors(sensors, vehicle, np.random.default_rng(seed))
    s0 = plant.state
    obs = StateObserver(observer, replace(P, mu=model_mu),
                        StateEstimate(0.0, s0[X], s0[Y], 0.0, vx_initial_estimate, 0.0, 0.0, 0.0))
    ts, truth, est, beta, samples = [], [], [], [], []
    u = np.zeros(3)
    for k in range(round(seconds / DT)):
        t = k * DT
        state = plant.state
        for sample in sens.sample(t, state, plant.imu_specific_force(state, u)):
            samples.append(sample)
            obs.update(sample)
        e = obs.estimate()
        ts.append(t)
        truth.append(state)
        est.append([e.x, e.y, e.theta, e.vx, e.vy, e.gamma])
        beta.append(e.beta)
        u = np.array([20.0 * (steering_target(t) - state[DELTA]), 15.0, 15.0])
        plant.step(u, 10)
    return Run(np.array(ts), np.array(truth), np.array(est), np.array(beta), samples, obs)


@pytest.fixture(scope="module")
def run() -> Run:
    return double_lane_change()


@pytest.fixture(scope="module")
def naive() -> Run:
    """The same run, but a history shorter than the lag: late fixes are fused as if current."""
    return double_lane_change(observer=ObserverParams(history_s=0.01))


def test_maneuver_is_evasive(run: Run) -> None:
    """The test drive excites the lateral dynamics (otherwise the accuracy tests below prove nothing)."""
    assert np.max(np.abs(run.truth[:, DELTA])) == pytest.approx(0.15, abs=0.01)
    assert np.max(np.abs(run.beta)) > 0.03
    assert np.max(np.abs(run.truth[:, GAMMA])) > 0.4
    assert np.ptp(run.truth[:, Y]) > 1.5


def test_sideslip_and_lateral_velocity_are_estimated(run: Run) -> None:
    keep = run.t >= 1.0
    beta_err = float(np.sqrt(np.mean((run.beta_est[keep] - run.beta[keep]) ** 2)))
    beta_rms = float(np.sqrt(np.mean(run.beta[keep] ** 2)))
    assert beta_err < 0.005
    assert beta_err < 0.1 * beta_rms  # the estimate explains over 90 % of the sideslip
    assert run.rms(VY) < 0.03


def test_yaw_rate_heading_and_speed_are_estimated(run: Run) -> None:
    assert run.rms(GAMMA) < 0.005  # gyro noise is 0.002 rad/s
    keep = run.t >= 1.0
    assert np.max(np.abs(run.est[keep, THETA] - run.truth[keep, THETA])) < 0.02
    assert run.rms(VX) < 0.05


def test_converges_from_a_wrong_initial_speed(run: Run) -> None:
    """Started 1.5 m/s slow: the first wheel-speed fix removes most of it (prior σ 0.2 m/s against
    0.1 m/s: the gain is 0.8), the next few the rest."""
    error = np.abs(run.est[:, VX] - run.truth[:, VX])
    assert 0.2 < error[0] < 0.4  # after the samples at t = 0: 1.5 · (1 − 0.8) = 0.3
    assert np.all(error[run.t >= 0.1] < 0.1)


def test_position_error_is_bounded_between_fixes(run: Run) -> None:
    after_first_fix = run.t >= LAG + DT
    assert np.max(run.position_error[after_first_fix]) < 0.15


def test_lag_compensation_beats_fusing_late_fixes_as_current(run: Run, naive: Run) -> None:
    """Ignoring the lag puts the car where it was ``lag`` seconds ago: an error of about v·lag."""
    keep = run.t >= 1.0
    travel = V0 * LAG
    naive_rms = float(np.sqrt(np.mean(naive.position_error[keep] ** 2)))
    compensated_rms = float(np.sqrt(np.mean(run.position_error[keep] ** 2)))
    assert 0.6 * travel < naive_rms < 1.2 * travel
    assert compensated_rms < 0.1 * travel
    assert compensated_rms < 0.1 * naive_rms


def test_without_replay_a_late_fix_is_fused_on_arrival_as_if_current(run: Run, naive: Run) -> None:
    """``replay_late_gps: false``: the filter of a car without a history, which fuses the stale fix as current — what
    a history shorter than the lag does — and so carries the v·lag error the replay removes."""
    off = double_lane_change(observer=ObserverParams(replay_late_gps=False))
    np.testing.assert_allclose(off.est, naive.est, rtol=0.0, atol=1e-9)
    assert np.max(np.abs(off.est[:, :2] - run.est[:, :2])) > 0.5 * V0 * LAG


def test_late_fix_replay_equals_the_fix_delivered_on_time(run: Run) -> None:
    """Same seed, lag 0 (same noise draws): once a late fix is delivered both filters agree to round-off."""
    on_time = double_lane_change(sensors=SensorParams(gps_lag_s=0.0))
    assert sum(isinstance(s, GpsSample) for s in on_time.samples) == 8
    since_fix = np.mod(run.t + 1e-9, 1.0)
    agreed = since_fix >= LAG  # between a fix's delivery and the next fix's measurement
    assert np.count_nonzero(agreed) > 500
    np.testing.assert_allclose(run.est[agreed], on_time.est[agreed], rtol=0.0, atol=1e-9)
    # … and they differ while the late fix is still on its way
    waiting = (since_fix > 0.005) & (since_fix < LAG - 0.005) & (run.t > 1.0)
    assert np.max(np.abs(run.est[waiting, :2] - on_time.est[waiting, :2])) > 1e-4


def test_deterministic_for_a_seed(run: Run) -> None:
    again = double_lane_change(seconds=3.0)
    n = len(again.t)
    assert again.samples == run.samples[: len(again.samples)]
    assert np.array_equal(again.est, run.est[:n])
    other = double_lane_change(seed=12, seconds=3.0)
    assert not np.array_equal(other.est, run.est[:n])


def _ticks(samples: list[Any]) -> list[list[Any]]:
    """The samples grouped by delivery time, as the sensors deliver them at each tick."""
    ticks: list[list[Any]] = []
    for sample in samples:
        if ticks and ticks[-1][0].t == sample.t:
            ticks[-1].append(sample)
        else:
            ticks.append([sample])
    return ticks


@pytest.mark.parametrize(("estimate_mu", "eps"), [(False, True), (True, True), (False, False)])
def test_update_all_is_update_one_by_one_bit_for_bit(run: Run, estimate_mu: bool, eps: bool) -> None:
    """The lockstep loop's batched update (IMU and wheel speeds fused in one compiled call) against one
    sample at a time, over 8 s with late GPS fixes (whose replays fuse the pairs again); also with μ
    estimated (no fusion) and without EPS samples (the fused pair ends a tick)."""
    params = ObserverParams(estimate_mu=estimate_mu)
    start = StateEstimate(0.0, 0.0, 0.0, 0.0, 5.5, 0.0, 0.0, 0.0)
    single, batched = StateObserver(params, P, start), StateObserver(params, P, start)
    fused = 0
    if not estimate_mu:  # (with μ estimated every sample goes through update)
        inner = batched._imu_wheel_fn

        def counting(*args: Any) -> Any:
            nonlocal fused
            fused += 1
            return inner(*args)

        batched._imu_wheel_fn = counting
    ticks = _ticks([s for s in run.samples if eps or not isinstance(s, EpsSample)])
    assert sum(isinstance(s, GpsSample) for s in run.samples) == 8
    for tick in ticks:
        for sample in tick:
            single.update(sample)
        batched.update_all(tick)
        assert batched.estimate() == single.estimate()
        assert np.array_equal(batched.covariance, single.covariance)
        assert batched.mu_estimate == single.mu_estimate
    # each tick once, and the 20 ticks of the GPS lag again at each of the 8 late fixes
    assert fused == (0 if estimate_mu else len(ticks) + 8 * round(LAG / DT))


def test_update_all_stops_at_an_invalid_sample_as_one_by_one_does() -> None:
    imu, wheel = ImuSample(0.51, 0.1, 0.3, 0.05), WheelSpeedSample(0.51, V0 / P.r, V0 / P.r)
    bad_wheel, bad_imu = WheelSpeedSample(0.51, 1.0, math.inf), ImuSample(0.51, math.nan, 0.3, 0.05)
    # a bad wheel-speed sample after a good IMU sample: the IMU sample is fused, then the error
    reference, batched = _fresh(), _fresh()
    reference.update(imu)
    with pytest.raises(ValueError, match=r"sample\.omega_rr = inf is invalid"):
        batched.update_all([imu, bad_wheel, EpsSample(0.51, 0.0)])
    assert batched.estimate() == reference.estimate() != _fresh().estimate()
    # a bad IMU sample first: nothing is fused
    untouched = _fresh()
    with pytest.raises(ValueError, match=r"sample\.ax = nan is invalid"):
        untouched.update_all([bad_imu, wheel])
    assert untouched.estimate() == _fresh().estimate()
    # and the filter goes on from there exactly as one fed sample by sample
    batched.update_all([ImuSample(0.52, 0.1, 0.3, 0.05), WheelSpeedSample(0.52, V0 / P.r, V0 / P.r)])
    reference.update(ImuSample(0.52, 0.1, 0.3, 0.05))
    reference.update(WheelSpeedSample(0.52, V0 / P.r, V0 / P.r))
    assert batched.estimate() == reference.estimate()


def test_estimated_friction_removes_the_sideslip_bias_of_a_wrong_model() -> None:
    """Plant μ = 0.35, observer model μ = 0.5: the cornering stiffness is 43 % too high."""
    fixed = double_lane_change(plant_mu=0.35, model_mu=0.5)
    adaptive = double_lane_change(observer=ObserverParams(estimate_mu=True), plant_mu=0.35, model_mu=0.5)
    keep = fixed.t >= 1.0

    def beta_rms(r: Run) -> float:
        return float(np.sqrt(np.mean((r.beta_est[keep] - r.beta[keep]) ** 2)))

    assert fixed.observer.mu_estimate == 0.5
    assert adaptive.observer.mu_estimate == pytest.approx(0.35, abs=0.03)
    assert beta_rms(fixed) > 0.01
    assert beta_rms(adaptive) < beta_rms(fixed) / 3.0


def test_asynchronous_samples_lose_no_propagation_time() -> None:
    """IMU on the 10 ms grid, wheels 5 ms and EPS 6 ms later: straight running gives x = v t."""
    v = 7.0
    obs = StateObserver(ObserverParams(), P, StateEstimate(0.0, 0.0, 0.0, 0.0, v, 0.0, 0.0, 0.0))
    for k in range(1, 301):
        obs.update(ImuSample(k * DT, 0.0, 0.0, 0.0))
        obs.update(WheelSpeedSample(k * DT + 0.005, v / P.r, v / P.r))
        obs.update(EpsSample(k * DT + 0.006, 0.0))
    e = obs.estimate()
    assert e.t == pytest.approx(3.006)
    assert e.x == pytest.approx(v * e.t, rel=1e-9)
    assert e.vx == pytest.approx(v, rel=1e-9) and e.y == 0.0 and e.vy == 0.0


def test_finite_and_at_rest_at_standstill() -> None:
    plant = VehiclePlant(P)
    plant.reset(initial_state(P, x=3.0, vx=0.0))
    sens = Sensors(SensorParams(), P, np.random.default_rng(5))
    obs = StateObserver(ObserverParams(), P, StateEstimate(0.0, 3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
    u = np.zeros(3)
    for k in range(3000):  # 30 s, 30 GPS fixes
        state = plant.state
        for sample in sens.sample(k * DT, state, plant.imu_specific_force(state, u)):
            obs.update(sample)
        plant.step(u, 10)
    e = obs.estimate()
    values = (e.x, e.y, e.theta, e.vx, e.vy, e.gamma, e.beta)
    assert all(math.isfinite(v) for v in values)
    assert abs(e.x - 3.0) < 0.05 and abs(e.y) < 0.05
    assert abs(e.vx) < 0.05 and abs(e.vy) < 0.05 and abs(e.gamma) < 0.005
    cov = obs.covariance
    assert np.all(np.isfinite(cov)) and np.allclose(cov, cov.T, atol=1e-12)
    assert np.min(np.linalg.eigvalsh(0.5 * (cov + cov.T))) > 0.0


def _fresh() -> StateObserver:
    obs = StateObserver(ObserverParams(), P, StateEstimate(0.0, 0.0, 0.0, 0.0, V0, 0.0, 0.0, 0.0))
    for k in range(1, 51):
        obs.update(ImuSample(k * DT, 0.0, 0.3, 0.05))
        obs.update(WheelSpeedSample(k * DT, V0 / P.r, V0 / P.r))
        obs.update(EpsSample(k * DT, 0.02))
    return obs


def test_rejects_out_of_order_and_invalid_samples_and_stays_unchanged() -> None:
    obs = _fresh()
    before = obs.estimate()
    with pytest.raises(ValueError, match=r"sample\.t = 0\.3 is invalid: older than the last sample at 0\.5"):
        obs.update(ImuSample(0.3, 0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match=r"sample\.ay = nan is invalid"):
        obs.update(ImuSample(0.51, 0.0, float("nan"), 0.0))
    with pytest.raises(ValueError, match=r"sample\.omega_rr = inf is invalid"):
        obs.update(WheelSpeedSample(0.51, 1.0, float("inf")))
    with pytest.raises(ValueError, match=r"sample\.t_measured = 0\.6 is invalid: after the fix's delivery"):
        obs.update(GpsSample(0.51, 0.6, 3.5, 0.0, V0, 0.0))
    with pytest.raises(TypeError, match="is not a sensor sample"):
        obs.update(before)  # type: ignore[arg-type]
    assert obs.estimate() == before
    # a sample stamped with the last sample's time is in order
    obs.update(EpsSample(0.5, 0.02))
    assert obs.estimate() == before


def test_rejected_samples_leave_no_trace_in_the_replay_history() -> None:
    """A late fix after rejected samples replays exactly what a filter that never saw them replays."""
    clean, dirty = _fresh(), _fresh()
    for k in range(51, 81):
        for obs in (clean, dirty):
            obs.update(ImuSample(k * DT, 0.0, 0.3, 0.05))
        with pytest.raises(TypeError):
            dirty.update("not a sample")  # type: ignore[arg-type]
        with pytest.raises(ValueError):
            dirty.update(ImuSample(k * DT, math.nan, 0.0, 0.0))
    fix = GpsSample(0.8, 0.6, 4.3, 0.01, V0, 0.02)
    clean.update(fix)
    dirty.update(fix)
    assert dirty.estimate() == clean.estimate()
    assert clean.estimate().y != _fresh().estimate().y  # the fix did move the estimate


def test_reset_round_trip_and_fresh_behaviour() -> None:
    start = StateEstimate(2.0, 10.0, -1.0, 0.1, 6.0, 0.2, 0.05, 0.03)
    obs = _fresh()
    obs.reset(start)
    assert obs.estimate() == start
    fresh = StateObserver(ObserverParams(), P, start)
    for k in range(1, 41):
        for o in (obs, fresh):
            o.update(ImuSample(2.0 + k * DT, 0.1, 1.2, 0.2))
            o.update(WheelSpeedSample(2.0 + k * DT, 6.0 / P.r, 6.0 / P.r))
    late = GpsSample(2.4, 2.2, 11.3, -0.8, 6.0, 0.8)
    obs.update(late)
    fresh.update(late)
    assert obs.estimate() == fresh.estimate()


def test_parameters_are_range_checked() -> None:
    with pytest.raises(ParamError, match=r"q_vy = -1\.0 is invalid"):
        ObserverParams(q_vy=-1.0)
    with pytest.raises(ParamError, match=r"mu_min = 1\.0 is invalid: expected below mu_max = 0\.5"):
        ObserverParams(mu_min=1.0, mu_max=0.5)

