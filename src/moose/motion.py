"""Motion control (Sec. V, Fig. 3): PI speed controller, torque distribution law, feedback EPS.

Speed control.  The nominal plant from one rear motor's torque to its wheel
speed is P_n(s) = 1 / (J_n s), J_n = J_ωr + r² (m/2)(1 − λ_n), λ_n = 0.05
(each rear wheel carries half the car).  With C(s) = K_p + K_i / s the closed
loop's characteristic polynomial is J_n s² + K_p s + K_i; placing both poles
at s = −ω_c (the paper's −1 rad/s) gives K_p = 2 ω_c J_n, K_i = ω_c² J_n.
The loop runs on the wheel-speed error ω* − v̂_x / r, with v̂_x from the
observer (Fig. 3).

Feed-forward C_v,ff.  The FBL's reference v_x* = v_x + t_s v̇_x* asks for
the speed to change by t_s v̇_x* over one planning period; the controller
ramps its internal reference linearly to v_x* over ``t_ramp`` (= t_s) and
feeds forward the nominal plant's inverse on that ramp, T_ff = J_n ω̇*.

Torque distribution law (TDL).  Equal split: both rear motors get the speed
controller's per-wheel torque, clipped at ±T_max.  The paper's planners give no
yaw-moment request, and an equal split adds no yaw moment of its own.

Anti-windup: the integrator holds while the torque is saturated in the
direction of the error (conditional integration).

Feedback EPS C_δ,fb.  δ̇_cmd = K_δ (δ* − δ_meas) with δ* clipped to ±δ_max
and δ̇_cmd to ±δ̇_max: a first-order steering response with time constant
1 / K_δ (default 50 ms).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from .params import VehicleParams, check, positive, unit_interval
from .signals import Reference, StateEstimate


@dataclasses.dataclass(frozen=True)
class MotionParams:
    """Motion-controller parameters."""

    pole: float = 1.0
    """ω_c (rad/s): both closed-loop poles of the speed loop at −ω_c (paper: −1 rad/s)."""
    slip_nominal: float = 0.05
    """λ_n of the nominal plant P_n(s)."""
    t_ramp: float = 0.2
    """Duration of the reference ramp to each new v_x* (s): the planning period."""
    k_delta: float = 20.0
    """EPS feedback gain K_δ (1/s)."""

    def __post_init__(self) -> None:
        for name in ("pole", "t_ramp", "k_delta"):
            check(name, getattr(self, name), positive, "a positive number")
        check("slip_nominal", self.slip_nominal, unit_interval, "a slip ratio in [0, 1]")


class MotionController:
    """SPC + TDL + FB-EPS; ``step`` returns the plant input [δ̇_cmd, T_rl, T_rr]."""

    def __init__(self, params: MotionParams, vehicle: VehicleParams) -> None:
        self.params = params
        self.vehicle = vehicle
        self.J_n = vehicle.J_wr + vehicle.r**2 * 0.5 * vehicle.m * (1.0 - params.slip_nominal)
        self.k_p = 2.0 * params.pole * self.J_n
        self.k_i = params.pole**2 * self.J_n
        self.reset()

    def reset(self) -> None:
        self._integral = 0.0
        self._target: float | None = None
        self._ramp_v = 0.0
        self._slope = 0.0

    def _ramp(self, target: float, vx_hat: float, dt: float) -> tuple[float, float]:
        """Internal speed reference and its slope, ramping to each new ``target``."""
        if self._target is None:
            self._ramp_v = vx_hat
        if target != self._target:
            self._target = target
            self._slope = (target - self._ramp_v) / self.params.t_ramp
        remaining = self._target - self._ramp_v
        step = self._slope * dt
        if abs(step) >= abs(remaining) or step * remaining <= 0.0:
            self._ramp_v, self._slope = self._target, 0.0
        else:
            self._ramp_v += step
        return self._ramp_v, self._slope

    def step(self, reference: Reference, estimate: StateEstimate, delta_measured: float, dt: float) -> np.ndarray:
        p = self.vehicle
        v_ref, slope = self._ramp(reference.vx, estimate.vx, dt)
        error = (v_ref - estimate.vx) / p.r
        feed_forward = self.J_n * slope / p.r
        torque = feed_forward + self.k_p * error + self.k_i * self._integral
        saturated = abs(torque) >= p.T_max and torque * error > 0.0
        if not saturated:
            self._integral += error * dt
        torque = min(max(torque, -p.T_max), p.T_max)
        delta_ref = min(max(reference.delta, -p.delta_max), p.delta_max)
        rate = min(max(self.params.k_delta * (delta_ref - delta_measured), -p.delta_rate_max), p.delta_rate_max)
        return np.array([rate, torque, torque])
