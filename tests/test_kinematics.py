"""The planners' kinematic model, eq. (skin), under exact zero-order hold (moose.planner.kinematics): exact
against closed forms and a fine integration, the same in CasADi as in floats, and the one rollout behind
the MPC's and the MSF's predictions and the blended path."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from moose.config import load_config
from moose.planner.kinematics import kinematic_rollout, kinematic_step
from moose.planner.step import PlanningRecord, PlanningStep, blend_path
from moose.signals import Blend, Obstacle, StateEstimate, Threat

T_S = 0.2


def test_exact_hold_prediction() -> None:
    a = np.array([[1.5, -2.0]] * 5)
    pred = kinematic_rollout(np.array([1.0, 2.0, 7.0, 0.5]), a, 0.2)
    t = 0.2 * np.arange(6)
    np.testing.assert_allclose(pred[:, 0], 1.0 + 7.0 * t + 0.75 * t**2, atol=1e-12)
    np.testing.assert_allclose(pred[:, 1], 2.0 + 0.5 * t - 1.0 * t**2, atol=1e-12)
    np.testing.assert_allclose(pred[:, 2:], [[7.0 + 1.5 * s, 0.5 - 2.0 * s] for s in t], atol=1e-12)
    assert pred[1, 1] != pred[0, 1] + 0.2 * 0.5  # unlike Euler, the first input moves y(k+1)


def test_rollout_is_exact_for_piecewise_constant_acceleration() -> None:
    rng = np.random.default_rng(0)
    accel = rng.uniform(-6.0, 6.0, (10, 2))
    state = np.array([1.0, -2.0, 6.0, 0.5])
    out = kinematic_rollout(state, accel, T_S)
    # independent: fine semi-analytic integration (velocity exact, position by the trapezoidal rule)
    n = 2000
    dt = T_S / n
    p, vel = state[:2].copy(), state[2:].copy()
    for k in range(10):
        for _ in range(n):
            v_next = vel + dt * accel[k]
            p = p + 0.5 * dt * (vel + v_next)
            vel = v_next
        np.testing.assert_allclose(out[k + 1], np.concatenate([p, vel]), atol=1e-9)


def test_the_symbolic_step_predicts_what_the_rollout_reports() -> None:
    """The MPC's cost predicts with the step on CasADi symbols; its plans report the rollout on floats."""
    rng = np.random.default_rng(1)
    state, accel = np.array([3.0, -0.4, 6.5, 0.3]), rng.uniform(-6.0, 6.0, (10, 2))
    s, a = ca.SX.sym("s", 4), ca.SX.sym("a", 10, 2)
    x = (s[0], s[1], s[2], s[3])
    rows = []
    for k in range(10):
        x = kinematic_step(x, (a[k, 0], a[k, 1]), T_S)
        rows.append(ca.horzcat(*x))
    symbolic = np.array(ca.Function("rollout", [s, a], [ca.vertcat(*rows)])(state, accel))
    np.testing.assert_allclose(symbolic, kinematic_rollout(state, accel, T_S)[1:], rtol=0, atol=1e-12)


@pytest.fixture(scope="module")
def record() -> tuple[PlanningStep, StateEstimate, PlanningRecord]:
    """One combined planning instant at 7 m/s, 12 m before a 2 m wide danger zone."""
    step = PlanningStep(load_config(), "combined")
    estimate = StateEstimate(0.0, 0.0, 0.1, 0.02, 7.0, 0.2, 0.05, 0.0)
    threat = Threat(0.0, Obstacle(12.0, 14.0, -0.5, 2.0), 12.0 / 7.0, 2.0, 0.5, 1, 0.0)
    return step, estimate, step.plan(0.0, estimate, threat, 7.0)


@pytest.mark.parametrize("planner", ["mpc", "msf"])
def test_each_plan_predicts_the_one_rollout_bit_for_bit(
        record: tuple[PlanningStep, StateEstimate, PlanningRecord], planner: str) -> None:
    step, estimate, rec = record
    plan = getattr(rec, planner)
    start = np.array([estimate.x, estimate.y, estimate.vX, estimate.vY])
    np.testing.assert_array_equal(plan.predicted, kinematic_rollout(start, plan.accel, step.grid.t_s))
    # the blended path of a plan applied alone is that plan's own prediction, bit for bit
    np.testing.assert_array_equal(blend_path(Blend(1.0, plan.accel), estimate, step.grid.t_s), plan.predicted)
