"""The planners' kinematic model, eq. (skin): a point mass p̈ = a in the global frame, state
[x, y, v_X, v_Y], input [v̇_X, v̇_Y], discretised over a planning period with the input held.

The discretisation is the exact zero-order hold, p⁺ = p + t_s v + t_s²/2 a, v⁺ = v + t_s a (exact
for a double integrator; forward Euler would give y(k+1) = y(k) whatever the input, so the first
predicted step could not react; docs/modelling.md, "MPC").  It is written once, here: the MPC's cost
(:mod:`moose.planner.mpc.cost`) predicts with :func:`kinematic_step`, and the MPC's and MSF's
``PlanResult.predicted`` and the blended path (:func:`moose.planner.step.blend_path`) are
:func:`kinematic_rollout`.  Light (NumPy only): the ``weight_fbl`` node uses it.
"""
from __future__ import annotations

from typing import Any

import numpy as np


def kinematic_step(state: Any, accel: Any, t_s: float) -> tuple[Any, Any, Any, Any]:
    """eq. (skin) over one period t_s with ``accel`` held: the next (x, y, v_X, v_Y).

    Floats or CasADi symbols alike (the MPC builds its cost from the symbolic step).
    """
    x, y, vX, vY = state
    aX, aY = accel
    h = 0.5 * t_s * t_s
    return x + t_s * vX + h * aX, y + t_s * vY + h * aY, vX + t_s * aX, vY + t_s * aY


def kinematic_rollout(state: np.ndarray, accel: np.ndarray, t_s: float) -> np.ndarray:
    """(N + 1, 4) states [x, y, v_X, v_Y] from ``state`` under (N, 2) accelerations, each held for t_s:
    :func:`kinematic_step` applied N times."""
    rows = [tuple(np.asarray(state, dtype=float).reshape(4).tolist())]
    for a in np.asarray(accel, dtype=float).reshape(-1, 2).tolist():  # on Python floats: the same sums, faster
        rows.append(kinematic_step(rows[-1], a, t_s))
    return np.array(rows, dtype=float)
