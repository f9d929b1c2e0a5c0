"""MPC planner: barrier sign, Example 2 of the paper, statuses, safety of the solution, mirror symmetry."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from moose.mpc import MpcParams, MpcPlanner, SolverCaps, j_safe, kinematic_rollout, y_safe
from moose.params import ParamError, VehicleParams
from moose.signals import Obstacle, PlannerInput, StateEstimate, Threat

VEHICLE = VehicleParams()


def threat(w: float = 2.6, x_min: float = 10.0, side: int = 1, length: float = 2.0) -> Threat:
    y_lo, y_hi = (w - 2 * w, w) if side > 0 else (-w, w)
    return Threat(0.0, Obstacle(x_min, x_min + length, y_lo, y_hi), x_min / 7.0, w, 1.0, side, 0.0)


def straight(v: float = 7.0, x: float = 0.0, y: float = 0.0) -> StateEstimate:
    return StateEstimate(0.0, x, y, 0.0, v, 0.0, 0.0, 0.0)


def test_barrier_keeps_the_ego_above_the_sigmoid() -> None:
    ys = float(y_safe(0.0, 7.0, 10.0, 2.6, 0.3))
    assert ys == pytest.approx(2.6, rel=0.01)  # at tau = 1.4 s the barrier is already up
    # cost falls as the ego moves to the safe side, and is finite (quadratic) on the wrong side
    costs = [float(j_safe(y, ys, 0.1)) for y in (-1.0, 0.0, 1.0, 2.0, 3.0, 4.0)]
    assert all(a > b for a, b in zip(costs, costs[1:]))
    assert all(math.isfinite(c) for c in costs)
    # far from the obstacle the barrier is down: y_safe(x_obs - 4 v_X) = w / 2
    assert float(y_safe(10.0 - 28.0, 7.0, 10.0, 2.6, 0.3)) == pytest.approx(1.3)


def test_notes_problem_evades_to_the_safe_side_and_clears() -> None:
    planner = MpcPlanner(MpcParams(), VEHICLE)
    result = planner.plan(PlannerInput(0.0, straight(), threat(), 7.0, None))
    assert result.status in ("converged", "capped")
    assert np.all(np.isfinite(result.accel)) and math.isfinite(result.cost)
    assert np.all(np.abs(result.accel) <= 6.0 + 1e-9)
    pred = result.predicted
    assert pred[0] == pytest.approx([0.0, 0.0, 7.0, 0.0])
    np.testing.assert_allclose(pred, kinematic_rollout(pred[0], result.accel, 0.2), atol=1e-9)
    beside = pred[(pred[:, 0] >= 10.0) & (pred[:, 0] <= 12.0)]
    assert len(beside) and np.all(beside[:, 1] > 0.0)  # steering left, away from the obstacle centre
    assert result.accel[0, 1] > 3.0


def test_mirrored_side_gives_the_mirrored_solution() -> None:
    planner = MpcPlanner(MpcParams(), VEHICLE)
    left = planner.plan(PlannerInput(0.0, straight(), threat(side=1), 7.0, None))
    right = planner.plan(PlannerInput(0.0, straight(), threat(side=-1), 7.0, None))
    np.testing.assert_allclose(left.accel[:, 0], right.accel[:, 0], atol=1e-6)
    np.testing.assert_allclose(left.accel[:, 1], -right.accel[:, 1], atol=1e-6)


def test_example_2_converged_solution_brakes() -> None:
    """Example 2: N_p = 2, v = 5, x_obs = w = 1, normalised inputs.

    The paper reports [0.00, 0.53] (equal weights) and [-0.35, 1.00] (eta = 0.5, 0.25,
    0.05, 0.2).  The obstacle is 0.2 s ahead: with the intended barrier and exact-hold
    prediction no steering clears it inside the horizon, and the converged optimum of
    both weight sets is full braking with no steering (docs/design.md, "Example 2").
    """
    inp = PlannerInput(0.0, straight(v=5.0), threat(w=1.0, x_min=1.0), 5.0, None)
    caps = SolverCaps(max_iter=300, max_fun_evals=2000)
    for eta in ((0.25, 0.25, 0.25, 0.25), (0.5, 0.25, 0.05, 0.2)):
        result = MpcPlanner(MpcParams(N_p=2, eta=eta, caps=caps), VEHICLE).plan(inp)
        assert result.status == "converged"
        u = result.accel[0] / 6.0
        assert u[0] == pytest.approx(-1.0, abs=1e-3) and abs(u[1]) < 0.05


def test_lane_keeping_without_threat_and_speed_never_reverses() -> None:
    planner = MpcPlanner(MpcParams(), VEHICLE)
    result = planner.plan(PlannerInput(0.0, straight(y=1.0), None, 7.0, None, y_lane=0.0))
    assert result.accel[0, 1] < 0.0  # back towards the lane
    braking = planner.plan(PlannerInput(0.0, straight(v=1.0), threat(x_min=3.0), 0.0, np.full((10, 2), -6.0)))
    assert np.all(braking.predicted[:, 2] > -0.2)


def test_statuses() -> None:
    capped = MpcPlanner(MpcParams(caps=SolverCaps(max_iter=1, max_fun_evals=10)), VEHICLE)
    assert capped.plan(PlannerInput(0.0, straight(), threat(), 7.0, None)).status == "capped"
    late = MpcPlanner(MpcParams(time_budget_s=1e-9), VEHICLE)
    assert late.plan(PlannerInput(0.0, straight(), threat(), 7.0, None)).status == "over_budget"
    bad = MpcPlanner(MpcParams(), VEHICLE).plan(
        PlannerInput(0.0, dataclasses.replace(straight(), x=float("nan")), threat(), 7.0, None))
    assert bad.status == "failed" and np.all(np.isfinite(bad.accel)) and bad.cost == math.inf


def test_warm_start_from_a_good_guess_is_not_worse() -> None:
    planner = MpcPlanner(MpcParams(), VEHICLE)
    cold = planner.plan(PlannerInput(0.0, straight(), threat(), 7.0, None))
    warm = planner.plan(PlannerInput(0.0, straight(), threat(), 7.0, cold.accel))
    assert warm.cost <= cold.cost + 1e-6


def test_parameters_are_validated() -> None:
    with pytest.raises(ParamError, match="eta"):
        MpcParams(eta=(0.5, 0.5, 0.5, 0.5))
    with pytest.raises(ParamError, match="max_iter_ls"):
        MpcParams(max_iter_ls=20)
