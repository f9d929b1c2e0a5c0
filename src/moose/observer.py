"""State observer (Sec. III, Fig. 3): β, γ, θ, v_x, v_y and the position from IMU, GPS, wheel speeds and EPS.

An extended Kalman filter on x̂ = [x, y, θ, v_x, v_y, γ].  Process model: the
single-track dynamics of eqs. (trajdef), (eom), (fy), (alphas) with the
measured steering angle δ (EPS) and the IMU's longitudinal specific force a_x
as inputs (v̇_x = a_x + v_y γ, eq. (dvxnl)); speeds in the slip denominators
bounded below by ``v_low`` as in the plant.  Measurements:

* IMU yaw rate γ, and the IMU lateral specific force a_y against the model's
  (F_yf cos δ + F_yr) / m — this is what makes v_y (so β) observable;
* rear wheel speeds: v_x ≈ r (ω_rl + ω_rr) / 2 (slip is absorbed by a larger
  noise);
* GPS x, y, v_X, v_Y, delivered ``lag`` seconds after ``t_measured``.  The
  filter keeps a short history of snapshots and the samples since; a late
  fix restores the snapshot at its measurement time, is fused there, and the
  later samples are replayed (exact re-propagation; at 1 Hz this costs about
  20 predict steps per fix).

Prediction runs at each IMU sample (explicit Euler over the sample interval).
"""
from __future__ import annotations

import dataclasses
import math
from collections import deque
from functools import lru_cache
from typing import Any, Union

import casadi as ca
import numpy as np

from .ccompile import compile_function
from .params import VehicleParams, check, non_negative, positive
from .signals import EpsSample, GpsSample, ImuSample, StateEstimate, WheelSpeedSample
from .tire import pacejka
from .vehicle import symbolic_params, vehicle_vector

Sample = Union[ImuSample, GpsSample, WheelSpeedSample, EpsSample]


@dataclasses.dataclass(frozen=True)
class ObserverParams:
    """Noise model (SI units, standard deviations) and history length."""

    mu_model: float = 0.0
    """Friction of the observer's tyre model; 0 uses the vehicle's μ (ROS 2 parameters cannot be null)."""
    q_position: float = 0.05
    q_yaw: float = 0.002
    q_vx: float = 0.3
    q_vy: float = 0.3
    q_yaw_rate: float = 0.3
    """Process noise densities (per √s) of x/y, θ, v_x, v_y, γ."""
    r_yaw_rate: float = 0.003
    r_lateral_accel: float = 0.3
    """IMU a_y against the model: sensor noise plus tyre-model error (m/s²)."""
    r_wheel_speed: float = 0.1
    r_gps_position: float = 0.03
    r_gps_velocity: float = 0.05
    history_s: float = 1.5
    """How far back a late GPS fix can be fused (s)."""

    def __post_init__(self) -> None:
        check("mu_model", self.mu_model, non_negative, "a friction coefficient (0: the vehicle's)")
        for f in dataclasses.fields(self)[1:]:
            check(f.name, getattr(self, f.name), positive, "a positive number")


class StateObserver:
    """EKF with delayed-GPS re-propagation; ``update`` takes samples in time order."""

    def __init__(self, params: ObserverParams, vehicle: VehicleParams, initial: StateEstimate | None = None) -> None:
        self.params = params
        self.vehicle = vehicle
        self._mu = params.mu_model if params.mu_model > 0.0 else vehicle.mu
        self._pv = vehicle_vector(vehicle)
        q = np.array([params.q_position, params.q_position, params.q_yaw, params.q_vx, params.q_vy, params.q_yaw_rate])
        self._q = q**2
        self._r_imu = np.array([params.r_yaw_rate**2, params.r_lateral_accel**2])
        self.reset(initial or StateEstimate(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))

    def reset(self, estimate: StateEstimate) -> None:
        self._x = np.array([estimate.x, estimate.y, estimate.theta, estimate.vx, estimate.vy, estimate.gamma], dtype=float)
        self._P = np.diag([0.05, 0.05, 0.01, 0.2, 0.2, 0.05]) ** 2
        self._t = estimate.t
        self._delta = estimate.delta
        self._ax = 0.0
        self._history: deque[tuple[float, np.ndarray, np.ndarray, float, float, Sample]] = deque()

    def estimate(self) -> StateEstimate:
        x = self._x
        return StateEstimate(self._t, float(x[0]), float(x[1]), float(x[2]), float(x[3]), float(x[4]), float(x[5]),
                             float(self._delta))

    # -- model (compiled) ----------------------------------------------------
    def _predict(self, dt: float) -> None:
        if dt <= 0.0:
            return
        self._x, self._P = _ekf()["predict"](self._x, self._P, self._ax, self._delta, dt, self._pv, self._mu, self._q)
        self._P = self._P.reshape(6, 6, order="F")

    def _correct(self, H: np.ndarray, innovation: np.ndarray, R: np.ndarray) -> None:
        """Kalman update with diagonal R, done as sequential scalar updates (exact for independent noise)."""
        x0 = self._x
        for row, nu, r in zip(H, innovation, np.diag(R)):
            PHt = self._P @ row
            gain = PHt / (row @ PHt + r)
            self._x = self._x + gain * (nu - row @ (self._x - x0))
            self._P = self._P - np.outer(gain, PHt)

    # -- samples -----------------------------------------------------------
    def update(self, sample: Sample) -> None:
        """Fuse one sample; samples must come in delivery-time order."""
        if sample.t + 1e-9 < self._t:
            raise ValueError(f"sample.t = {sample.t!r} is invalid: older than the last sample at {self._t!r}")
        if isinstance(sample, GpsSample):
            self._fuse_late_gps(sample)
            return
        # x and P are replaced, never modified in place, so the snapshot can share them
        self._history.append((self._t, self._x, self._P, self._delta, self._ax, sample))
        while self._history and self._history[0][0] < sample.t - self.params.history_s:
            self._history.popleft()
        self._apply(sample)

    def _apply(self, sample: Sample) -> None:
        p, prm = self.vehicle, self.params
        if isinstance(sample, ImuSample):
            dt = max(sample.t - self._t, 0.0)
            x, P = _ekf()["imu"](self._x, self._P, self._ax, self._delta, dt, sample.yaw_rate, sample.ay,
                                 self._pv, self._mu, self._q, self._r_imu)
            self._x, self._P = x, P.reshape(6, 6, order="F")
            self._t = sample.t
            self._ax = sample.ax
        elif isinstance(sample, WheelSpeedSample):
            self._t = max(self._t, sample.t)
            v_wheels = 0.5 * p.r * (sample.omega_rl + sample.omega_rr)
            PHt = self._P[:, 3].copy()  # H = e_vx
            gain = PHt / (PHt[3] + prm.r_wheel_speed**2)
            self._x = self._x + gain * (v_wheels - self._x[3])
            self._P = self._P - np.outer(gain, PHt)
        elif isinstance(sample, EpsSample):
            self._t = max(self._t, sample.t)
            self._delta = sample.delta
        elif isinstance(sample, GpsSample):
            self._gps_correct(sample)
        else:
            raise TypeError(f"sample = {sample!r} is not a sensor sample")

    def _gps_correct(self, fix: GpsSample) -> None:
        prm, x = self.params, self._x
        theta, vx, vy = x[2], x[3], x[4]
        c, s = math.cos(theta), math.sin(theta)
        H = np.zeros((4, 6))
        H[0, 0] = H[1, 1] = 1.0
        H[2, 2], H[2, 3], H[2, 4] = -vx * s - vy * c, c, -s
        H[3, 2], H[3, 3], H[3, 4] = vx * c - vy * s, s, c
        h = np.array([x[0], x[1], vx * c - vy * s, vx * s + vy * c])
        z = np.array([fix.x, fix.y, fix.vX, fix.vY])
        R = np.diag([prm.r_gps_position**2] * 2 + [prm.r_gps_velocity**2] * 2)
        self._correct(H, z - h, R)

    def _fuse_late_gps(self, fix: GpsSample) -> None:
        """Fuse a fix at its measurement time and replay the samples delivered since."""
        history = self._history
        index = None
        for i in range(len(history) - 1, -1, -1):
            if history[i][0] <= fix.t_measured + 1e-9:
                index = i
                break
        if index is None:
            self._gps_correct(fix)  # older than the history: fuse now (documented degradation)
            return
        t0, x0, P0, delta0, ax0, _ = history[index]
        replay = [entry[5] for entry in list(history)[index:]]
        now = self._t
        self._t, self._x, self._P, self._delta, self._ax = t0, x0.copy(), P0.copy(), delta0, ax0
        # predict from the snapshot to the measurement time, fuse, then replay
        self._predict(fix.t_measured - t0)
        self._t = max(t0, fix.t_measured)
        self._gps_correct(fix)
        rebuilt: deque = deque(list(history)[:index])
        for sample in replay:
            rebuilt.append((self._t, self._x, self._P, self._delta, self._ax, sample))
            self._apply(sample)
        self._history = rebuilt
        self._t = max(self._t, now)


@lru_cache(maxsize=None)
def _ekf() -> dict[str, Any]:
    """Compiled EKF steps, parametric in the vehicle: ``predict`` and ``imu`` (predict + γ, a_y updates).

    The process model is eqs. (trajdef), (eom) with the Pacejka law eq. (fy) on the slip
    angles eq. (alphas) (speeds bounded below by v_low); Jacobians by CasADi's AD.
    """
    x = ca.SX.sym("x", 6)
    P = ca.SX.sym("P", 6, 6)
    ax, delta, dt, mu = ca.SX.sym("ax"), ca.SX.sym("delta"), ca.SX.sym("dt"), ca.SX.sym("mu")
    z_gamma, z_ay = ca.SX.sym("z_gamma"), ca.SX.sym("z_ay")
    q, r = ca.SX.sym("q", 6), ca.SX.sym("r", 2)
    pv, p = symbolic_params()
    theta, vx, vy, gamma = x[2], x[3], x[4], x[5]
    v_bar = ca.fmax(vx, p.v_low)
    fyf = pacejka(delta - (vy + p.lf * gamma) / v_bar, mu * p.Fzf, p.By, p.Cy, ops=ca)
    fyr = pacejka(-(vy - p.lr * gamma) / v_bar, mu * p.Fzr, p.By, p.Cy, ops=ca)
    lateral = (fyf * ca.cos(delta) + fyr) / p.m  # the IMU's a_y
    xdot = ca.vertcat(vx * ca.cos(theta) - vy * ca.sin(theta), vx * ca.sin(theta) + vy * ca.cos(theta), gamma,
                      ax + vy * gamma, lateral - vx * gamma, (fyf * ca.cos(delta) * p.lf - fyr * p.lr) / p.Izz)
    x_pred = x + dt * xdot
    F = ca.jacobian(x_pred, x)
    P_pred = F @ P @ F.T + ca.diag(q * dt)
    predict = ca.Function("moose_ekf_predict", [x, P, ax, delta, dt, pv, mu, q], [x_pred, P_pred])
    # sequential scalar updates at the predicted state: gamma, then a_y (linearised)
    h_ay = ca.Function("h_ay", [x, delta, pv, mu], [lateral])
    H_ay = ca.jacobian(lateral, x)
    xs, Ps = x_pred, P_pred
    for H, innovation, noise in (
        (ca.DM([[0, 0, 0, 0, 0, 1]]), z_gamma - x_pred[5], r[0]),
        (ca.substitute(H_ay, x, x_pred), z_ay - h_ay(x_pred, delta, pv, mu), r[1]),
    ):
        PHt = Ps @ H.T
        gain = PHt / (H @ PHt + noise)
        xs = xs + gain * (innovation - H @ (xs - x_pred))
        Ps = Ps - gain @ PHt.T
    imu = ca.Function("moose_ekf_imu", [x, P, ax, delta, dt, z_gamma, z_ay, pv, mu, q, r], [xs, 0.5 * (Ps + Ps.T)])
    return {name: _compiled(fn) for name, fn in (("predict", predict), ("imu", imu))}


def _compiled(fn: ca.Function) -> Any:
    compiled = compile_function(fn)
    if compiled is not None:
        return lambda *args: [np.asarray(v) for v in compiled(*args)]
    return lambda *args: [np.asarray(v, dtype=float).ravel(order="F") for v in fn(*args)]
