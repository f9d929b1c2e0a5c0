"""Pacejka tire laws, eq. (fy), and the inverse of the lateral law.

The lateral law F_y = μ F_z sin(C_y atan(B_y α)) is odd and increases in α up to
the peak slip α_peak = tan(π / (2 C_y)) / B_y, where F_y = μ F_z.  The same
"magic formula" without shift terms gives the longitudinal force from the slip
ratio λ with (B_x, C_x).  Functions accept floats, NumPy arrays and CasADi
symbols alike (:func:`pacejka` only uses ``sin`` and ``arctan`` of the namespace
``ops``: ``numpy`` or ``casadi``), so the plant, the maneuver table and the FBL share one definition.
"""
from __future__ import annotations

import math
from types import ModuleType
from typing import Any

import numpy as np


def pacejka(slip: Any, mu_fz: Any, B: float, C: float, ops: ModuleType = np) -> Any:
    """Magic formula F = μ F_z sin(C atan(B s)) for a slip ``s`` (angle or ratio)."""
    return mu_fz * ops.sin(C * ops.arctan(B * slip))


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
