"""Single-track plant of the FPEV2-Kanon: eqs. (trajdef), (eom), (fy), (alphas), Table I.

State ``X = [x, y, θ, v_x, v_y, γ, ω_rl, ω_rr, δ]`` (global position and yaw,
body velocities and yaw rate, rear wheel speeds, steering angle); input
``U = [δ̇_cmd, T_rl, T_rr]`` (EPS motor rate command, rear in-wheel motor
torques); their indices are named in :mod:`moose.state`.

* Forces: eq. (eom) with the steering angle kept (the plant does not make the
  small-angle simplification of eq. (eomdyn)); front wheels undriven and
  unbraked (F_xf = 0); static axle loads (Table I gives no CoG height).
* Lateral tyres: eq. (fy) on the slip angles of eq. (alphas) with β ≈ v_y / v_x,
  written with the bounded speed ``v̄ = max(v_x, v_low)`` in the denominators:
  α_f = δ − (v_y + l_f γ) / v̄, α_r = (l_r γ − v_y) / v̄ (:func:`moose.tire.lateral_forces`).
* Rear tyres: longitudinal magic formula (B_x, C_x) on the slip ratio
  λ = (r ω − v_w) / max(|v_w|, r|ω|, v_low) of each wheel, wheel ground speed
  v_w = v_x ∓ γ b/2, load F_zr / 2 each; wheel dynamics J_ωr ω̇ = T − r F_x;
  the difference of the rear forces adds the yaw moment (F_x,rr − F_x,rl) b/2.
* Low speed: ``v_low`` bounds every slip denominator.  Linearising the slip
  dynamics of one rear wheel, d(rω − v_x)/dt = −(rω − v_x)/τ_λ with
  1/τ_λ = k_x (r²/J_ωr + 2/m) / v̄ and k_x = μ (F_zr/2) B_x C_x
  (:func:`slip_time_constant`): τ_λ ≈ 0.42 ms per m/s of v̄ at μ = 1.  RK4 is
  stable for dt < 2.785 τ_λ, so ``v_low = 2 m/s`` keeps the 1 kHz integration
  stable down to standstill for μ up to ≈ 2.3 (checked when a plant is built);
  at rest with zero torque every slip and force is zero, so the car stays at rest.
* Actuators: the steering angle follows the EPS rate command saturated at
  ±δ̇_max and stops at ±δ_max; motor torques are clipped at ±T_max.  δ(t) is
  integrated exactly inside each RK4 step (it is piecewise linear in time:
  δ(t) = clip(δ₀ + δ̇ t, ±δ_max)), so no RK4 stage sees a steering angle beyond
  the limit, and δ stops at the limit without overshoot or chattering.

The dynamics are written once as CasADi expressions.  ``step(u, n)`` runs n
RK4 steps with u held in one call of a function compiled to C (``ccompile``;
CasADi's virtual machine when no C compiler is present), which also returns the
IMU specific force at the new state, because a CasADi call from Python costs
more than the integration itself.
"""
from __future__ import annotations

import dataclasses
import math
from functools import lru_cache
from typing import Any

import casadi as ca
import numpy as np

from .ccompile import CompiledFunction, bind, compile_function
from .params import ParamError, VehicleParams
from .state import (
    DELTA,
    GAMMA,
    N_INPUT,
    N_STATE,
    OMEGA_RL,
    OMEGA_RR,
    STEER_RATE,
    THETA,
    TORQUE_RL,
    TORQUE_RR,
    VX,
    VY,
    X,
    Y,
)
from .tire import Axles, lateral_forces, pacejka

RK4_STABILITY = 2.785
"""RK4's stability limit on the negative real axis, |λ dt| < 2.785."""


def dynamics(state: Any, u: Any, p: VehicleParams) -> tuple[Any, Any]:
    """State derivative and IMU specific force [a_x, a_y] (CasADi expressions), eqs. (trajdef), (eom), (fy)."""
    theta, vx, vy, gamma = state[THETA], state[VX], state[VY], state[GAMMA]
    omega_rl, omega_rr, delta = state[OMEGA_RL], state[OMEGA_RR], state[DELTA]
    rate_cmd = ca.fmin(ca.fmax(u[STEER_RATE], -p.delta_rate_max), p.delta_rate_max)
    t_rl = ca.fmin(ca.fmax(u[TORQUE_RL], -p.T_max), p.T_max)
    t_rr = ca.fmin(ca.fmax(u[TORQUE_RR], -p.T_max), p.T_max)
    v_bar = ca.fmax(vx, p.v_low)
    fyf, fyr = lateral_forces(vy, gamma, delta, v_bar, Axles.of(p, p.mu), ops=ca)  # bounded denominators
    # rear longitudinal slip and force per wheel
    half = 0.5 * p.track
    forces = []
    for omega, v_w in ((omega_rl, vx - gamma * half), (omega_rr, vx + gamma * half)):
        denom = ca.fmax(ca.fmax(ca.fabs(v_w), p.r * ca.fabs(omega)), p.v_low)
        slip = (p.r * omega - v_w) / denom
        forces.append(pacejka(slip, 0.5 * p.mu * p.Fzr, p.Bx, p.Cx, ops=ca))
    fx_rl, fx_rr = forces
    fxr = fx_rl + fx_rr
    # eq. (eom), F_xf = 0
    sum_fx = -fyf * ca.sin(delta) + fxr
    sum_fy = fyf * ca.cos(delta) + fyr
    sum_mz = fyf * ca.cos(delta) * p.lf - fyr * p.lr + (fx_rr - fx_rl) * half
    ax, ay = sum_fx / p.m, sum_fy / p.m
    xdot = ca.vertcat(
        vx * ca.cos(theta) - vy * ca.sin(theta),
        vx * ca.sin(theta) + vy * ca.cos(theta),
        gamma,
        ax + vy * gamma,
        ay - vx * gamma,
        sum_mz / p.Izz,
        (t_rl - p.r * fx_rl) / p.J_wr,
        (t_rr - p.r * fx_rr) / p.J_wr,
        steering_rate(delta, rate_cmd, p),
    )
    return xdot, ca.vertcat(ax, ay)


def steering_rate(delta: Any, rate: Any, p: VehicleParams) -> Any:
    """δ̇ of the EPS actuator: the (saturated) rate, zero when it pushes past ±δ_max."""
    blocked = ca.logic_or(ca.logic_and(delta >= p.delta_max, rate > 0), ca.logic_and(delta <= -p.delta_max, rate < 0))
    return ca.if_else(blocked, 0, rate)


def slip_time_constant(params: VehicleParams, v_bar: float) -> float:
    """Time constant τ_λ (s) of one rear wheel's slip dynamics at the slip denominator ``v_bar``.

    Near zero slip F_x ≈ k_x (rω − v_x)/v̄ with k_x = μ (F_zr/2) B_x C_x (the slope
    of eq. (fy)'s magic formula at the origin); J_ωr ω̇ = −r F_x and m v̇_x ≈ 2 F_x
    (both wheels) give d(rω − v_x)/dt = −k_x (r²/J_ωr + 2/m)/v̄ · (rω − v_x).
    """
    k_x = params.mu * 0.5 * params.Fzr * params.Bx * params.Cx
    return v_bar / (k_x * (params.r**2 / params.J_wr + 2.0 / params.m))


PARAM_FIELDS = tuple(f.name for f in dataclasses.fields(VehicleParams))
CHUNK = 10
"""Steps per compiled call; longer advances loop over it."""


def vehicle_vector(params: VehicleParams) -> np.ndarray:
    """The numeric values behind :func:`symbolic_params`."""
    return np.array([float(getattr(params, name)) for name in PARAM_FIELDS])


def symbolic_params() -> tuple[ca.SX, VehicleParams]:
    """A VehicleParams whose fields are CasADi symbols (its derived properties follow)."""
    vector = ca.SX.sym("p", len(PARAM_FIELDS))
    params = object.__new__(VehicleParams)
    for i, name in enumerate(PARAM_FIELDS):
        object.__setattr__(params, name, vector[i])
    return vector, params


@lru_cache(maxsize=None)
def _functions() -> tuple[ca.Function, ca.Function, dict[int, ca.Function | CompiledFunction]]:
    """Dynamics, one RK4 step and the compiled n-step chunks, parametric in (vehicle, dt)."""
    s = ca.SX.sym("x", N_STATE)
    u = ca.SX.sym("u", N_INPUT)
    dt = ca.SX.sym("dt")
    pv, p = symbolic_params()
    xdot, force = dynamics(s, u, p)
    f = ca.Function("f", [s, u, pv], [xdot, force])
    # the steering angle is piecewise linear in time: exact inside the step
    rate = ca.fmin(ca.fmax(u[STEER_RATE], -p.delta_rate_max), p.delta_rate_max)

    def delta_at(c: float) -> ca.SX:
        return ca.fmin(ca.fmax(s[DELTA] + rate * (c * dt), -p.delta_max), p.delta_max)

    def stage(x: ca.SX, c: float) -> ca.SX:
        return f(ca.vertcat(x[:DELTA], delta_at(c)), u, pv)[0]

    k1 = stage(s, 0.0)
    k2 = stage(s + 0.5 * dt * k1, 0.5)
    k3 = stage(s + 0.5 * dt * k2, 0.5)
    k4 = stage(s + dt * k3, 1.0)
    nxt = s + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    nxt = ca.vertcat(nxt[:DELTA], delta_at(1.0))
    step = ca.Function("rk4", [s, u, pv, dt], [nxt])
    chunks: dict[int, ca.Function | CompiledFunction] = {}
    for n in (1, CHUNK):
        x = s
        for _ in range(n):
            x = step(x, u, pv, dt)
        # common subexpressions (the steering angle of the two mid stages, the parameters' products) once
        chunk = ca.Function(f"moose_plant_chunk_{n}", [s, u, pv, dt], [x, f(x, u, pv)[1]], {"cse": True})
        chunks[n] = compile_function(chunk) or chunk
    return f, step, chunks


def rk4_step_function() -> ca.Function:
    """One RK4 step ``rk4(x, u, p, dt) -> x_next`` (CasADi), parametric in ``vehicle_vector(params)``."""
    return _functions()[1]


class VehiclePlant:
    """The plant integrated with fixed-step RK4 (default 1 kHz)."""

    def __init__(self, params: VehicleParams, dt: float = 1e-3) -> None:
        if not (isinstance(dt, (int, float)) and 0.0 < dt < math.inf):
            raise ParamError(f"dt = {dt!r} is invalid: expected a positive step (s)")
        tau = slip_time_constant(params, params.v_low)
        if dt >= RK4_STABILITY * tau:
            raise ParamError(
                f"dt = {dt!r} is invalid: RK4 needs dt < {RK4_STABILITY * tau:.3g} s for the wheel-slip time "
                f"constant {tau:.3g} s at v_low = {params.v_low} m/s, mu = {params.mu} (raise v_low or lower dt)"
            )
        self.params = params
        self.dt = float(dt)
        self._f, _, chunks = _functions()
        self._p = vehicle_vector(params)
        # the n-step chunks with this plant's parameters and step bound once
        self._chunk, self._single = bind(chunks[CHUNK], self._p, self.dt), bind(chunks[1], self._p, self.dt)
        self._state = initial_state(params)
        self._t = 0.0
        self._force: tuple[float, float] | None = None

    @property
    def state(self) -> np.ndarray:
        return self._state.copy()

    @property
    def t(self) -> float:
        return self._t

    def reset(self, state: np.ndarray, t: float = 0.0) -> None:
        """Set the state (and the time); the steering angle must lie within ±δ_max."""
        state = np.asarray(state, dtype=float)
        if state.shape != (N_STATE,) or not np.all(np.isfinite(state)):
            raise ValueError(f"state = {state!r} is invalid: expected {N_STATE} finite values")
        if abs(state[DELTA]) > self.params.delta_max:
            raise ValueError(f"state[DELTA] = {state[DELTA]!r} is invalid: expected |delta| <= {self.params.delta_max}")
        self._state = state.copy()
        self._t = float(t)
        self._force = None

    def step(self, u: np.ndarray, n: int = 1) -> np.ndarray:
        """Advance ``n`` steps of ``dt`` with the input ``u`` held; returns the new state."""
        u = np.asarray(u, dtype=float)
        if u.shape != (N_INPUT,) or not all(map(math.isfinite, u.tolist())):
            raise ValueError(f"u = {u!r} is invalid: expected {N_INPUT} finite plant inputs")
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f"n = {n!r} is invalid: expected a positive number of steps")
        state = self._state
        chunk, single = self._chunk, self._single
        for _ in range(n // CHUNK):
            state, force = chunk(state, u)
        for _ in range(n % CHUNK):
            state, force = single(state, u)
        self._state = np.asarray(state, dtype=float).ravel()
        a_x, a_y = np.asarray(force, dtype=float).ravel().tolist()
        self._force = (a_x, a_y)
        self._t += n * self.dt
        return self._state.copy()

    @property
    def specific_force(self) -> tuple[float, float]:
        """IMU specific force at the current state under the input of the last ``step`` (computed by that step)."""
        if self._force is None:
            raise RuntimeError("specific_force is defined after the first step; use imu_specific_force(state, u)")
        return self._force

    def derivatives(self, state: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Ẋ at (state, u)."""
        return np.asarray(self._f(state, u, self._p)[0], dtype=float).ravel()

    def imu_specific_force(self, state: np.ndarray, u: np.ndarray) -> tuple[float, float]:
        """Body specific force (a_x, a_y) = (v̇_x − v_y γ, v̇_y + v_x γ) an IMU at the CoG measures."""
        force = np.asarray(self._f(state, u, self._p)[1], dtype=float).ravel()
        return float(force[0]), float(force[1])


def initial_state(params: VehicleParams, x: float = 0.0, y: float = 0.0, theta: float = 0.0,
                  vx: float = 0.0) -> np.ndarray:
    """Straight running at ``vx``: wheels rolling without slip, δ = 0."""
    state = np.zeros(N_STATE)
    state[[X, Y, THETA, VX]] = (x, y, theta, vx)
    state[[OMEGA_RL, OMEGA_RR]] = vx / params.r
    return state
