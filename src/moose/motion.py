"""Motion control (Sec. V, Fig. 3): PI speed controller, torque distribution law, feedback EPS.

Speed control (SPC).  The nominal plant from one rear motor's torque to its
wheel speed is P_n(s) = 1 / (J_n s), J_n = J_ωr + r² (m/2)(1 − λ_n),
λ_n = 0.05 (Sec. V; each rear wheel drives half the car).  With the PI law
C(s) = K_p + K_i / s the closed loop's characteristic polynomial is

    1 + C(s) P_n(s) = 0  ⇔  J_n s² + K_p s + K_i = 0,

and placing both poles at s = −ω_c (the paper's −1 rad/s), i.e. matching
J_n (s + ω_c)² = J_n s² + 2 ω_c J_n s + ω_c² J_n, gives

    K_p = 2 ω_c J_n,   K_i = ω_c² J_n.

The reference-to-speed response is (2 ω_c s + ω_c²) / (s + ω_c)²: a step of
the reference is followed as 1 − e^{−ω_c t} + ω_c t e^{−ω_c t} (the PI zero
gives e^{−2} ≈ 13.5 % overshoot at t = 2/ω_c).  The loop runs on the
wheel-speed error ω* − v̂_x / r, ω* = v_x*/r, with v̂_x from the observer
(Fig. 3), discretised at the motion-control rate (the ``dt`` of :meth:`step`;
forward-Euler integrator).

Feed-forward C_v,ff.  The FBL's reference v_x* = v_x + t_s v̇_x* asks for the
speed to change by t_s v̇_x* over one planning period; tracked by a 1 rad/s
loop alone the car would deliver only about t_s · 1 rad/s = 20 % of v̇_x*.  The
controller therefore ramps an internal reference linearly to each new v_x*
at the slope (v_x* − v_ref)/t_ramp (t_ramp = t_s), limited to the acceleration
the motors can give the nominal plant, r · accel_margin · T_max / J_n, and adds
the nominal plant's inverse on that ramp, T_ff = J_n ω̇_ref.  The feedback loop
then only corrects model error, and a feasible v̇_x* is delivered without lag.
The limit keeps the ramp from running away from a car whose motors saturate
(which would wind the error up and overshoot afterwards); its default share
accel_margin = 1 keeps the full torque available, because an emergency system
must not give away braking authority.

Torque distribution law (TDL).  Equal split: both rear motors get the speed
controller's per-wheel torque, each clipped at ±T_max.  The paper's planners
request no yaw moment, and an equal split adds none of its own (with equal
wheel loads it also maximises the traction available before either wheel
saturates).

The torque is limited as the motors are, |T| ≤ T_max and |Ṫ| ≤ Ṫ_max (the vehicle's
``torque_rate_max``, which the CAN bridge's guard enforces as well, so the lockstep loop
drives the car the bridge would).  Anti-windup: conditional integration — the integrator
holds while the torque is limited in the direction of the error.

Feedback EPS (C_δ,fb).  The FPEV2-Kanon's steering motor is speed-controlled
(Sec. V), so the command is a rate: δ̇_cmd = K_δ (δ* − δ_meas), δ* clipped
to ±δ_max, δ̇_cmd clipped to ±δ̇_max.  The steering then follows δ* as a first
order lag with time constant 1/K_δ; K_δ = 20 1/s (50 ms) is fast against the
5 Hz planning and the 1 rad/s speed loop, and at 100 Hz the discrete loop's
pole 1 − K_δ dt = 0.8 is real and positive (monotone, no ringing; K_δ dt ≤ 1 is
enforced).  Its effective time constant is −dt / ln(1 − K_δ dt) = 45 ms.
"""
from __future__ import annotations

import numpy as np

from .params import VehicleParams
from .schema import MotionParams
from .signals import Reference, StateEstimate


class MotionController:
    """SPC + TDL + FB-EPS; ``step`` returns the plant input [δ̇_cmd, T_rl, T_rr]."""

    def __init__(self, params: MotionParams, vehicle: VehicleParams) -> None:
        self.params = params
        self.vehicle = vehicle
        self.J_n = vehicle.J_wr + vehicle.r**2 * 0.5 * vehicle.m * (1.0 - params.slip_nominal)
        """Nominal inertia of P_n(s) seen by one motor (kg m^2)."""
        self.k_p = 2.0 * params.pole * self.J_n
        self.k_i = params.pole**2 * self.J_n
        self.accel_limit = vehicle.r * params.accel_margin * vehicle.T_max / self.J_n
        """Steepest reference ramp (m/s^2) the feed-forward asks for."""
        self.reset()

    def reset(self, torque: float = 0.0) -> None:
        """Forget the integrator and the reference ramp; ``torque`` is the motors' present torque (N m), from
        which the next output is rate-limited (another controller, the minimum-risk maneuver, drove them)."""
        self._integral = 0.0
        self._torque = float(torque)
        self._target: float | None = None
        self._ramp_v = 0.0
        self._slope = 0.0

    def _reference(self, target: float, vx_hat: float, dt: float) -> tuple[float, float]:
        """Internal speed reference and its slope: a linear, rate-limited ramp to each new ``target``."""
        if not self.params.feed_forward:
            return target, 0.0
        if self._target is None:
            self._ramp_v = vx_hat
        if target != self._target:
            self._target = target
            slope = (target - self._ramp_v) / self.params.t_ramp
            self._slope = min(max(slope, -self.accel_limit), self.accel_limit)
        remaining = target - self._ramp_v
        if abs(self._slope * dt) >= abs(remaining) or self._slope * remaining <= 0.0:
            self._ramp_v, self._slope = target, 0.0
        else:
            self._ramp_v += self._slope * dt
        return self._ramp_v, self._slope

    def step(self, reference: Reference, estimate: StateEstimate, delta_measured: float, dt: float) -> np.ndarray:
        """Plant input U = [δ̇_cmd, T_rl, T_rr] for the next ``dt`` seconds."""
        p = self.vehicle
        if not dt > 0.0 or self.params.k_delta * dt > 1.0:
            raise ValueError(f"dt = {dt!r} is invalid: expected 0 < dt <= 1/k_delta = {1.0 / self.params.k_delta}")
        v_ref, slope = self._reference(reference.vx, estimate.vx, dt)
        error = (v_ref - estimate.vx) / p.r
        feed_forward = self.J_n * slope / p.r
        torque = feed_forward + self.k_p * error + self.k_i * self._integral
        # the motors' limits: |T| ≤ T_max and |dT/dt| ≤ torque_rate_max (what the CAN bridge enforces too)
        step = p.torque_rate_max * dt
        low, high = max(-p.T_max, self._torque - step), min(p.T_max, self._torque + step)
        saturated = (torque >= high and error > 0.0) or (torque <= low and error < 0.0)
        if not saturated:
            self._integral += error * dt
        torque = min(max(torque, low), high)
        self._torque = torque
        # TDL: equal split
        delta_ref = min(max(reference.delta, -p.delta_max), p.delta_max)
        rate = min(max(self.params.k_delta * (delta_ref - delta_measured), -p.delta_rate_max), p.delta_rate_max)
        return np.array([rate, torque, torque])
