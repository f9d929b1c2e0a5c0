"""Feedback linearization (Sec. IV-C): planned accelerations → reference steering angle δ* and speed v_x*.

The global accelerations [v̇_X*, v̇_Y*] are rotated into the body frame,
[a_x, a_y] = R(−θ) [v̇_X*, v̇_Y*]; a_y is the body-frame inertial acceleration,
m a_y = m (v̇_y + γ v_x) = F_yf + F_yr (eq. (dvynl)).  The printed FBL formula
writes "− F_yr^{-1}(l_r γ / v_x − β)", which is dimensionally a force
subtracted from a force only if it reads F_yr(α_r): we subtract the rear
force at the current rear slip angle α_r = l_r γ / v_x − β (eq. (alr)),
invert the front law eq. (fyf) for the required front force on its monotone
branch (saturating at the peak slip), and add back β + l_f γ / v_x (eq. (alf)):

    δ* = β + l_f γ / v_x + F_yf⁻¹[ m a_y − F_yr(l_r γ / v_x − β) ],
    v_x* = v_x + t_s v̇_x*,   v̇_x* = a_x + v_y γ   (eq. (dvxnl)).

δ* is clipped to ±δ_max; speeds in the denominators are bounded below by
``VehicleParams.v_low`` as in the plant.
"""
from __future__ import annotations

import math

import numpy as np

from ..params import VehicleParams
from ..schema import FblParams
from ..signals import Reference, StateEstimate
from ..tire import Axles, inverse_lateral, pacejka


class FeedbackLinearization:
    """δ*, v_x* from the blended accelerations and the current estimate."""

    def __init__(self, params: FblParams, vehicle: VehicleParams, t_s: float) -> None:
        self.params = params
        self.vehicle = vehicle
        """The vehicle as the stack believes it (the planning μ)."""
        self.t_s = t_s
        """Planning sampling time (s): horizon of the speed reference."""
        self._axles = Axles.of(vehicle, vehicle.mu)

    def reference(self, accel: np.ndarray, estimate: StateEstimate) -> Reference:
        """δ* and v_x* for the global acceleration ``accel`` = [v̇_X*, v̇_Y*] at ``estimate``."""
        a_x, a_y = self._body(accel, estimate)
        vx_dot = a_x + estimate.vy * estimate.gamma
        vx_ref = max(estimate.vx + self.t_s * vx_dot, self.params.v_min_ref)
        return Reference(delta=self._steering(a_y, estimate), vx=float(vx_ref))

    def steering(self, accel: np.ndarray, estimate: StateEstimate) -> float:
        """δ* alone (what the motion-rate re-evaluation between planning instants needs)."""
        return self._steering(self._body(accel, estimate)[1], estimate)

    @staticmethod
    def _body(accel: np.ndarray, estimate: StateEstimate) -> tuple[float, float]:
        """[a_x, a_y] = R(−θ) [v̇_X*, v̇_Y*]."""
        aX, aY = float(accel[0]), float(accel[1])
        c, s = math.cos(estimate.theta), math.sin(estimate.theta)
        return c * aX + s * aY, -s * aX + c * aY

    def _steering(self, a_y: float, estimate: StateEstimate) -> float:
        p, axles = self.vehicle, self._axles
        v_bar = max(estimate.vx, p.v_low)
        beta = estimate.vy / v_bar
        alpha_r = p.lr * estimate.gamma / v_bar - beta
        f_front = p.m * a_y - pacejka(alpha_r, axles.mu_fzr, axles.B, axles.C)
        alpha_f = inverse_lateral(f_front, axles.mu_fzf, axles.B, axles.C)
        delta = beta + p.lf * estimate.gamma / v_bar + alpha_f
        return float(min(max(delta, -p.delta_max), p.delta_max))
