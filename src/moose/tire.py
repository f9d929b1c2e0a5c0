"""Slip angles, eq. (alphas), Pacejka tire laws, eq. (fy), and the inverse of the lateral law.

The lateral law F_y = μ F_z sin(C_y atan(B_y α)) is odd and increases in α up to
the peak slip α_peak = tan(π / (2 C_y)) / B_y, where F_y = μ F_z.  The same
"magic formula" without shift terms gives the longitudinal force from the slip
ratio λ with (B_x, C_x).  Functions accept floats, NumPy arrays and CasADi
symbols alike (they only use ``sin`` and ``arctan`` of the namespace ``ops``:
``numpy`` or ``casadi``), so the plant (:mod:`moose.vehicle`), the observer's
process model (:mod:`moose.observer`), the maneuver table (:mod:`moose.maneuver`)
and the FBL share one definition of the slip angles and the tyre forces.
"""
from __future__ import annotations

import math
from types import ModuleType
from typing import Any, NamedTuple

import numpy as np

from .params import VehicleParams


class Axles(NamedTuple):
    """What eqs. (alphas) and (fy) need of a vehicle: floats, or CasADi symbols in a compiled model."""

    lf: Any
    """CoG to front axle l_f (m)."""
    lr: Any
    """CoG to rear axle l_r (m)."""
    mu_fzf: Any
    """μ F_zf: the front axle's peak lateral force (N)."""
    mu_fzr: Any
    """μ F_zr: the rear axle's peak lateral force (N)."""
    B: Any
    """Lateral stiffness factor B_y."""
    C: Any
    """Lateral shape factor C_y."""

    @classmethod
    def of(cls, vehicle: VehicleParams, mu: Any) -> "Axles":
        """The axles of ``vehicle`` (numeric or symbolic) on a road of friction ``mu``, static loads."""
        return cls(vehicle.lf, vehicle.lr, mu * vehicle.Fzf, mu * vehicle.Fzr, vehicle.By, vehicle.Cy)


def pacejka(slip: Any, mu_fz: Any, B: Any, C: Any, ops: ModuleType = np) -> Any:
    """Magic formula F = μ F_z sin(C atan(B s)) for a slip ``s`` (angle or ratio)."""
    return mu_fz * ops.sin(C * ops.arctan(B * slip))


def slip_angles(vy: Any, gamma: Any, delta: Any, v_bar: Any, axles: Axles) -> tuple[Any, Any]:
    """(α_f, α_r), eq. (alphas) with β ≈ v_y / v̄: α_f = δ − (v_y + l_f γ) / v̄, α_r = (l_r γ − v_y) / v̄.

    ``v_bar`` is the longitudinal speed v_x as the caller bounds it: max(v_x, v_low) in the plant and
    the observer (a bounded denominator at standstill), the table's constant v_x > 0 in eq. (ymax).
    """
    return delta - (vy + axles.lf * gamma) / v_bar, (axles.lr * gamma - vy) / v_bar


def lateral_forces(vy: Any, gamma: Any, delta: Any, v_bar: Any, axles: Axles,
                   ops: ModuleType = np) -> tuple[Any, Any]:
    """(F_yf, F_yr), eq. (fy) at the slip angles of eq. (alphas) (:func:`slip_angles`)."""
    alpha_f, alpha_r = slip_angles(vy, gamma, delta, v_bar, axles)
    return (pacejka(alpha_f, axles.mu_fzf, axles.B, axles.C, ops),
            pacejka(alpha_r, axles.mu_fzr, axles.B, axles.C, ops))


def peak_slip(B: float, C: float) -> float:
    """Slip at which the magic formula peaks: tan(π / (2C)) / B (C > 1)."""
    return math.tan(math.pi / (2.0 * C)) / B


def inverse_lateral(force: Any, mu_fz: float, B: float, C: float) -> Any:
    """Slip angle giving ``force`` on the monotone branch |α| ≤ α_peak (NumPy).

    Forces beyond ±μ F_z saturate at ±α_peak: the inverse of eq. (fy) is only
    defined inside the monotone range, and the peak is where the tyre delivers
    the most it can.
    """
    if isinstance(force, (float, int)):
        ratio = min(max(force / mu_fz, -1.0), 1.0)
        return math.tan(math.asin(ratio) / C) / B
    ratios = np.clip(np.asarray(force, dtype=float) / mu_fz, -1.0, 1.0)
    alpha = np.tan(np.arcsin(ratios) / C) / B
    return alpha if np.ndim(alpha) else float(alpha)
