"""State observer (Sec. III, Fig. 3): β, γ, θ, v_x, v_y and the position from IMU, GPS, wheel speeds and EPS.

An extended Kalman filter on x̂ = [x, y, θ, v_x, v_y, γ] (optionally augmented
with the friction coefficient μ, see below).  Process model: the single-track
dynamics of eqs. (trajdef), (eom), (fy), (alphas) with the measured steering
angle δ (EPS) and the IMU's longitudinal specific force a_x as inputs
(v̇_x = a_x + v_y γ, eq. (dvxnl)); speeds in the slip denominators bounded below
by ``v_low`` as in the plant.  Measurements:

* IMU yaw rate γ, and the IMU lateral specific force a_y against the model's
  (F_yf cos δ + F_yr) / m — this is what makes v_y (so β) observable;
* rear wheel speeds: v_x ≈ r (ω_rl + ω_rr) / 2 (the mean of the two rear wheel
  ground speeds v_x ∓ γ b/2 is v_x; slip is absorbed by a larger noise);
* GPS x, y, v_X, v_Y, delivered ``lag`` seconds after ``t_measured``.  The
  filter keeps a short history of snapshots and the samples since; a late
  fix restores the snapshot at its measurement time, is fused there, and the
  later samples are replayed (exact re-propagation; at 1 Hz this costs about
  20 predict steps per fix).  A fix older than the history is fused on arrival, and so is every fix
  without ``replay_late_gps`` (as if it were current: the stale position a filter without a history uses).

The lockstep loop hands the filter each tick's samples at once (:meth:`StateObserver.update_all`):
the IMU and wheel-speed samples of one time are then fused in one compiled call that calls the two
steps in turn, with the same result bit for bit as one sample at a time (what the observer node does).

Prediction runs at each IMU sample (explicit Euler over the sample interval,
inputs held from the previous samples); a wheel-speed, EPS or GPS sample
stamped later than the last sample first predicts to its own time, so
asynchronous sensors lose no propagation time.  Invalid samples (not a sensor
record, non-finite fields, older than the last sample, a GPS fix measured after
its delivery) raise before they touch the filter, which stays as it was.

The lateral model's cornering stiffness is μ F_z B_y C_y, so a wrong model μ
biases v_y and β (measured in docs/modelling.md).  With ``estimate_mu`` the state
is augmented with μ as a random walk, observable through a_y, γ and the GPS
velocity whenever the tyres carry lateral force, and kept in [mu_min, mu_max].
"""
from __future__ import annotations

import math
import operator
from collections import deque
from functools import lru_cache
from typing import Any, Iterator, Sequence, Union

import casadi as ca
import numpy as np

from .ccompile import bind, compile_function
from .params import VehicleParams
from .schema import ObserverParams
from .signals import EpsSample, GpsSample, ImuSample, Sample, StateEstimate, WheelSpeedSample
from .state import GAMMA, N_MOTION, THETA, VX, VY, X, Y
from .tire import Axles, lateral_forces
from .vehicle import symbolic_params, vehicle_vector

_FIELDS: dict[type, tuple[str, ...]] = {
    ImuSample: ("t", "ax", "ay", "yaw_rate"),
    WheelSpeedSample: ("t", "omega_rl", "omega_rr"),
    EpsSample: ("t", "delta"),
    GpsSample: ("t", "t_measured", "x", "y", "vX", "vY"),
}
_GETTERS = {kind: operator.attrgetter(*fields) for kind, fields in _FIELDS.items()}
"""The fields of each sample type, read in one call."""
MU = N_MOTION
"""Index of μ in the augmented state, after the plant's motion states X … GAMMA (:mod:`moose.state`)."""


class StateObserver:
    """EKF with delayed-GPS re-propagation; ``update`` takes samples in time order."""

    def __init__(self, params: ObserverParams, vehicle: VehicleParams, initial: StateEstimate | None = None) -> None:
        self.params = params
        self.vehicle = vehicle
        self._mu = vehicle.mu  # the planning μ: the stack's one belief about the road
        if params.estimate_mu:
            self._mu = min(max(self._mu, params.mu_min), params.mu_max)
        self._n = N_MOTION + 1 if params.estimate_mu else N_MOTION
        pv = vehicle_vector(vehicle)
        q = [params.q_position, params.q_position, params.q_yaw, params.q_vx, params.q_vy, params.q_yaw_rate]
        q_squared = np.array(q + [params.q_mu] * (self._n - N_MOTION)) ** 2
        r_imu = np.array([params.r_yaw_rate**2, params.r_lateral_accel**2])
        # the EKF steps with this observer's constant inputs (vehicle, μ, noises) bound once
        fns = _ekf(params.estimate_mu)
        self._predict_fn = bind(fns["predict"], pv, self._mu, q_squared)
        self._imu_fn = bind(fns["imu"], pv, self._mu, q_squared, r_imu)
        self._wheel_fn = bind(fns["wheel"], params.r_wheel_speed**2)
        self._imu_wheel_fn = (bind(fns["imu_wheel"], pv, self._mu, q_squared, r_imu, params.r_wheel_speed**2)
                              if "imu_wheel" in fns else None)
        self._r_gps = np.array([params.r_gps_position**2] * 2 + [params.r_gps_velocity**2] * 2)
        self.reset(initial or StateEstimate(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))

    def reset(self, estimate: StateEstimate) -> None:
        """Restart from ``estimate`` (an estimated μ restarts at the vehicle's μ); forgets the history."""
        x = [estimate.x, estimate.y, estimate.theta, estimate.vx, estimate.vy, estimate.gamma]
        std = [0.05, 0.05, 0.01, 0.2, 0.2, 0.05]
        if self._n > MU:
            x.append(self._mu)
            std.append(self.params.mu_std0)
        self._x = np.array(x, dtype=float)
        self._P = np.diag(std) ** 2
        self._t = estimate.t
        self._delta = estimate.delta
        self._ax = 0.0
        self._history: deque[tuple[float, np.ndarray, np.ndarray, float, float, Sample]] = deque()

    def estimate(self) -> StateEstimate:
        """The estimate at the time of the last sample."""
        x = self._x.tolist()  # Python floats, as float() of each entry
        return StateEstimate(self._t, x[X], x[Y], x[THETA], x[VX], x[VY], x[GAMMA], float(self._delta))

    @property
    def mu_estimate(self) -> float:
        """The friction coefficient of the tyre model: estimated with ``estimate_mu``, else the vehicle's μ."""
        return float(self._x[MU]) if self._n > MU else self._mu

    @property
    def covariance(self) -> np.ndarray:
        """Error covariance of [x, y, θ, v_x, v_y, γ (, μ)] (a copy)."""
        return self._P.copy()

    # -- model (compiled) ----------------------------------------------------
    def _predict(self, dt: float) -> None:
        if dt <= 0.0:
            return
        self._x, P = self._predict_fn(self._x, self._P, self._ax, self._delta, dt)
        self._P = P.reshape(self._n, self._n, order="F")

    def _bound_mu(self) -> None:
        """Keep an estimated μ in [mu_min, mu_max] (projection; x̂ is replaced, never modified in place)."""
        if self._n > MU and not self.params.mu_min <= self._x[MU] <= self.params.mu_max:
            x = self._x.copy()
            x[MU] = min(max(x[MU], self.params.mu_min), self.params.mu_max)
            self._x = x

    def _correct(self, H: np.ndarray, innovation: np.ndarray, r: np.ndarray) -> None:
        """Kalman update with independent noises (variances ``r``), done as sequential scalar updates."""
        x0 = self._x
        for row, nu, var in zip(H, innovation, r):
            PHt = self._P @ row
            gain = PHt / (row @ PHt + var)
            self._x = self._x + gain * (nu - row @ (self._x - x0))
            self._P = self._P - np.outer(gain, PHt)

    # -- samples -----------------------------------------------------------
    def update(self, sample: Sample) -> None:
        """Fuse one sample; samples must come in delivery-time order.

        Raises ``TypeError`` for anything but the four sensor records and ``ValueError``
        for a non-finite field, a sample older than the last one, or a GPS fix measured
        after its delivery; the filter is left unchanged in each case.
        """
        self._validate(sample)
        if isinstance(sample, GpsSample):
            self._fuse_late_gps(sample)
            return
        # x and P are replaced, never modified in place, so the snapshot can share them
        history = self._history
        history.append((self._t, self._x, self._P, self._delta, self._ax, sample))
        oldest = sample.t - self.params.history_s
        while history and history[0][0] < oldest:
            history.popleft()
        self._apply(sample)

    def update_all(self, samples: Sequence[Sample]) -> None:
        """:meth:`update` on each of ``samples`` in order, with the same result bit for bit.

        An IMU sample directly followed by a wheel-speed sample of the same time (the sensors' usual
        100 Hz tick) is fused in one compiled call.  On an invalid sample the samples before it are
        fused and the error is raised, as the calls one by one would do.
        """
        for item in _paired(samples):
            if not isinstance(item, tuple):
                self.update(item)
            elif not self._imu_wheel(*item):
                self.update(item[0])
                self.update(item[1])

    def _imu_wheel(self, imu: ImuSample, wheel: WheelSpeedSample) -> bool:
        """Fuse an IMU and a wheel-speed sample of one time in one call; False (nothing fused) if one is invalid
        or μ is estimated (it is projected onto its bounds between the two updates)."""
        fused = self._imu_wheel_fn
        if fused is None:
            return False
        try:
            self._validate(imu)
            self._validate(wheel)
        except ValueError:
            return False
        history = self._history
        self._fuse_pair(fused, imu, wheel, history)
        oldest = wheel.t - self.params.history_s
        while history and history[0][0] < oldest:
            history.popleft()
        return True

    def _fuse_pair(self, fused: Any, imu: ImuSample, wheel: WheelSpeedSample, history: deque) -> None:
        """Fuse a valid IMU and wheel-speed sample of one time with ``fused`` (the compiled ``imu_wheel`` step),
        appending to ``history`` the snapshot before each, as :meth:`update` does."""
        history.append((self._t, self._x, self._P, self._delta, self._ax, imu))
        dt = max(imu.t - self._t, 0.0)
        v_wheels = 0.5 * self.vehicle.r * (wheel.omega_rl + wheel.omega_rr)
        x_imu, P_imu, x, P = fused(self._x, self._P, self._ax, self._delta, dt, imu.yaw_rate, imu.ay, v_wheels)
        n = self._n
        history.append((imu.t, x_imu, P_imu.reshape(n, n, order="F"), self._delta, imu.ax, wheel))
        self._x, self._P = x, P.reshape(n, n, order="F")
        self._t = imu.t
        self._ax = imu.ax

    def _validate(self, sample: Sample) -> None:
        getter = _GETTERS.get(type(sample))
        if getter is None:
            kind = next((k for k in _FIELDS if isinstance(sample, k)), None)  # a subclass of a sample type
            if kind is None:
                raise TypeError(f"sample = {sample!r} is not a sensor sample (ImuSample, GpsSample, "
                                "WheelSpeedSample or EpsSample)")
            getter = _GETTERS[kind]
        values = getter(sample)
        if not all(map(math.isfinite, values)):
            fields = next(f for k, f in _FIELDS.items() if isinstance(sample, k))
            name, value = next((n, v) for n, v in zip(fields, values) if not math.isfinite(v))
            raise ValueError(f"sample.{name} = {value!r} is invalid: expected a finite number")
        if sample.t + 1e-9 < self._t:
            raise ValueError(f"sample.t = {sample.t!r} is invalid: older than the last sample at {self._t!r}")
        if isinstance(sample, GpsSample) and sample.t_measured > sample.t + 1e-9:
            raise ValueError(f"sample.t_measured = {sample.t_measured!r} is invalid: "
                             f"after the fix's delivery at {sample.t!r}")

    def _advance(self, t: float) -> None:
        """Predict to ``t`` with the inputs held (no-op for a sample stamped with the last sample's time)."""
        if t > self._t:
            self._predict(t - self._t)
            self._t = t

    def _apply(self, sample: Sample) -> None:
        p = self.vehicle
        if isinstance(sample, ImuSample):
            dt = max(sample.t - self._t, 0.0)
            x, P = self._imu_fn(self._x, self._P, self._ax, self._delta, dt, sample.yaw_rate, sample.ay)
            self._x, self._P = x, P.reshape(self._n, self._n, order="F")
            self._bound_mu()
            self._t = sample.t
            self._ax = sample.ax
        elif isinstance(sample, WheelSpeedSample):
            self._advance(sample.t)
            v_wheels = 0.5 * p.r * (sample.omega_rl + sample.omega_rr)
            x, P = self._wheel_fn(self._x, self._P, v_wheels)
            self._x, self._P = x, P.reshape(self._n, self._n, order="F")
            self._bound_mu()
        elif isinstance(sample, EpsSample):
            self._advance(sample.t)
            self._delta = sample.delta
        else:
            raise TypeError(f"sample = {sample!r} is not a replayable sensor sample")

    def _gps_correct(self, fix: GpsSample) -> None:
        x = self._x
        theta, vx, vy = x[THETA], x[VX], x[VY]
        c, s = math.cos(theta), math.sin(theta)
        H = np.zeros((4, self._n))
        H[0, X] = H[1, Y] = 1.0
        H[2, THETA], H[2, VX], H[2, VY] = -vx * s - vy * c, c, -s
        H[3, THETA], H[3, VX], H[3, VY] = vx * c - vy * s, s, c
        h = np.array([x[X], x[Y], vx * c - vy * s, vx * s + vy * c])
        z = np.array([fix.x, fix.y, fix.vX, fix.vY])
        self._correct(H, z - h, self._r_gps)
        self._bound_mu()

    def _fuse_late_gps(self, fix: GpsSample) -> None:
        """Fuse a fix at its measurement time and replay the samples delivered since (without
        ``replay_late_gps``: at its delivery, as if it were current)."""
        if not self.params.replay_late_gps:
            self._advance(fix.t)
            self._gps_correct(fix)
            return
        if fix.t_measured >= self._t:  # not older than the filter: predict to it and fuse
            self._advance(fix.t_measured)
            self._gps_correct(fix)
            return
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
        entries = list(history)
        now = self._t
        self._t, self._x, self._P, self._delta, self._ax = t0, x0, P0, delta0, ax0
        # predict from the snapshot to the measurement time, fuse, then replay
        self._predict(fix.t_measured - t0)
        self._t = max(t0, fix.t_measured)
        self._gps_correct(fix)
        rebuilt: deque = deque(entries[:index])
        fused = self._imu_wheel_fn
        # the samples were validated on arrival; an IMU and wheel-speed pair is fused again
        for item in _paired([entry[5] for entry in entries[index:]]):
            if isinstance(item, tuple) and fused is not None:
                self._fuse_pair(fused, *item, rebuilt)
                continue
            for one in item if isinstance(item, tuple) else (item,):
                rebuilt.append((self._t, self._x, self._P, self._delta, self._ax, one))
                self._apply(one)
        self._history = rebuilt
        self._t = max(self._t, now)


def _paired(samples: Sequence[Sample]) -> Iterator[Union[Sample, tuple[ImuSample, WheelSpeedSample]]]:
    """``samples`` in order, except that an IMU sample directly followed by a wheel-speed sample of the same
    time comes as one (IMU, wheel-speed) pair: the sensors' usual tick, fused in one compiled call."""
    i, n = 0, len(samples)
    while i < n:
        sample, following = samples[i], samples[i + 1] if i + 1 < n else None
        if type(sample) is ImuSample and type(following) is WheelSpeedSample and following.t == sample.t:
            yield sample, following
            i += 2
        else:
            yield sample
            i += 1


@lru_cache(maxsize=None)
def _ekf(estimate_mu: bool = False) -> dict[str, Any]:
    """Compiled EKF steps, parametric in the vehicle: ``predict``, ``imu`` (predict + γ, a_y updates) and
    ``wheel`` (the wheel-speed update of v_x).

    The process model is eqs. (trajdef), (eom) with the Pacejka law eq. (fy) on the slip
    angles eq. (alphas) (speeds bounded below by v_low); Jacobians by CasADi's AD.  With
    ``estimate_mu`` the state has a seventh entry μ (μ̇ = 0 plus process noise) and the
    ``mu`` argument is unused.
    """
    n = N_MOTION + 1 if estimate_mu else N_MOTION
    x = ca.SX.sym("x", n)
    P = ca.SX.sym("P", n, n)
    ax, delta, dt, mu_in = ca.SX.sym("ax"), ca.SX.sym("delta"), ca.SX.sym("dt"), ca.SX.sym("mu")
    z_gamma, z_ay = ca.SX.sym("z_gamma"), ca.SX.sym("z_ay")
    q, r = ca.SX.sym("q", n), ca.SX.sym("r", 2)
    pv, p = symbolic_params()
    theta, vx, vy, gamma = x[THETA], x[VX], x[VY], x[GAMMA]
    mu = x[MU] if estimate_mu else mu_in
    v_bar = ca.fmax(vx, p.v_low)
    fyf, fyr = lateral_forces(vy, gamma, delta, v_bar, Axles.of(p, mu), ops=ca)
    lateral = (fyf * ca.cos(delta) + fyr) / p.m  # the IMU's a_y
    rates = [vx * ca.cos(theta) - vy * ca.sin(theta), vx * ca.sin(theta) + vy * ca.cos(theta), gamma,
             ax + vy * gamma, lateral - vx * gamma, (fyf * ca.cos(delta) * p.lf - fyr * p.lr) / p.Izz]
    xdot = ca.vertcat(*rates, *([ca.SX(0)] if estimate_mu else []))
    x_pred = x + dt * xdot
    F = ca.jacobian(x_pred, x)
    P_pred = F @ P @ F.T + ca.diag(q * dt)
    prefix = "moose_ekf_mu" if estimate_mu else "moose_ekf"
    predict = ca.Function(f"{prefix}_predict", [x, P, ax, delta, dt, pv, mu_in, q], [x_pred, P_pred])
    # sequential scalar updates at the predicted state: gamma, then a_y (linearised)
    h_ay = ca.Function("h_ay", [x, delta, pv, mu_in], [lateral])
    H_ay = ca.jacobian(lateral, x)
    e_gamma = ca.DM.zeros(1, n)
    e_gamma[0, GAMMA] = 1.0
    xs, Ps = x_pred, P_pred
    for H, innovation, noise in (
        (e_gamma, z_gamma - x_pred[GAMMA], r[0]),
        (ca.substitute(H_ay, x, x_pred), z_ay - h_ay(x_pred, delta, pv, mu_in), r[1]),
    ):
        PHt = Ps @ H.T
        gain = PHt / (H @ PHt + noise)
        xs = xs + gain * (innovation - H @ (xs - x_pred))
        Ps = Ps - gain @ PHt.T
    imu = ca.Function(f"{prefix}_imu", [x, P, ax, delta, dt, z_gamma, z_ay, pv, mu_in, q, r],
                      [xs, 0.5 * (Ps + Ps.T)])
    # the wheel-speed update: H = e_vx, a scalar Kalman update (gain = P e_vx / (P_vx,vx + r))
    z_v, r_v = ca.SX.sym("z_v"), ca.SX.sym("r_v")
    PHt = P[:, VX]
    gain = PHt / (PHt[VX] + r_v)
    wheel = ca.Function(f"{prefix}_wheel", [x, P, z_v, r_v], [x + gain * (z_v - x[VX]), P - ca.mtimes(gain, PHt.T)])
    steps = {"predict": predict, "imu": imu, "wheel": wheel}
    if not estimate_mu:  # (with μ estimated, μ is projected onto its bounds between the two updates)
        steps["imu_wheel"] = _imu_then_wheel(imu, wheel, f"{prefix}_imu_wheel")
    return {name: _compiled(fn) for name, fn in steps.items()}


def _imu_then_wheel(imu: ca.Function, wheel: ca.Function, name: str) -> ca.Function:
    """The sensors' usual 100 Hz tick in one call: ``imu`` then ``wheel`` on its result.

    ``(x, P, ax, delta, dt, z_gamma, z_ay, z_v, vehicle, mu, q, r, r_v) -> (x', P', x'', P'')``, where
    (x', P') is the state after the IMU sample (the wheel-speed sample's snapshot for a late GPS fix).
    The two steps are called, not re-derived, so the result is bit for bit that of the two calls.
    """
    args = [ca.MX.sym(imu.name_in(i), imu.sparsity_in(i)) for i in range(imu.n_in())]
    z_v, r_v = ca.MX.sym("z_v"), ca.MX.sym("r_v")
    x_imu, P_imu = imu(*args)
    x_wheel, P_wheel = wheel(x_imu, P_imu, z_v, r_v)
    inputs = [*args[:7], z_v, *args[7:], r_v]
    return ca.Function(name, inputs, [x_imu, P_imu, x_wheel, P_wheel])


def _compiled(fn: ca.Function) -> Any:
    compiled = compile_function(fn)
    if compiled is not None:
        return compiled  # returns NumPy arrays (copies) already
    return lambda *args: [np.asarray(v, dtype=float).ravel(order="F") for v in fn(*args)]
