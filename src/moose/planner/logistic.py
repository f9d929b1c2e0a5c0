"""The logistic function σ(z) = 1 / (1 + e^−z): the planners' one S-curve.

σ rises from 0 to 1 and is ½ at z = 0; it is evaluated as ½ (1 + tanh(z / 2)), which cannot
overflow for any z.  The weight function's factors rise with it (:mod:`moose.planner.weight`); the
MPC's sigmoid barrier eq. (ysafe) and its switch-off past the obstacle (:mod:`moose.planner.mpc.cost`)
fall, as σ(−a) = 1 / (1 + e^a).  Light (``math`` only unless CasADi is passed in).
"""
from __future__ import annotations

import math
from types import ModuleType
from typing import Any


def logistic(z: Any, ops: ModuleType = math) -> Any:
    """σ(z) = 1 / (1 + e^−z) = ½ (1 + tanh(z / 2)) of a float (``ops`` = math) or a CasADi symbol (casadi)."""
    return 0.5 * (1.0 + ops.tanh(0.5 * z))
