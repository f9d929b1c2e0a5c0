"""MSF planner: clears the danger zone on the kinematic model, mirrors, returns to the lane."""
from __future__ import annotations

import numpy as np
import pytest

from moose.maneuver import ManeuverParams, MaxSteeringTable, lateral_steering_index
from moose.msf import MsfParams, MsfPlanner
from moose.params import VehicleParams
from moose.signals import Obstacle, PlannerInput, StateEstimate, Threat

VEHICLE = VehicleParams()


@pytest.fixture(scope="module")
def table() -> MaxSteeringTable:
    return MaxSteeringTable.build(VEHICLE, ManeuverParams())


def closed_loop_on_kinematics(table: MaxSteeringTable, v: float, tau: float, w: float, side: int = 1) -> np.ndarray:
    """Re-plan at 5 Hz on the kinematic model, applying the first input each time."""
    planner = MsfPlanner(MsfParams(), table, VEHICLE)
    x_min = v * tau
    obstacle = Obstacle(x_min, x_min + 2.0, -w, w)
    state = np.array([0.0, 0.0, v, 0.0])
    path = [state]
    for k in range(40):
        est = StateEstimate(0.2 * k, state[0], state[1], 0.0, state[2], state[3], 0.0, 0.0)
        passed = state[0] > obstacle.x_max + 2.0
        tau_k = (x_min - state[0]) / state[2]
        threat = None if passed else Threat(0.2 * k, obstacle, tau_k, w,
                                            lateral_steering_index(w, tau_k, v, table), side, 0.0)
        plan = planner.plan(PlannerInput(0.2 * k, est, threat, v, None))
        assert np.all(np.abs(plan.accel) <= 6.0 + 1e-9)
        state = plan.predicted[1]
        path.append(state)
    return np.array(path)


@pytest.mark.parametrize("v, tau, w", [(5.0, 3.0, 2.4), (6.0, 3.0, 2.0), (7.0, 2.0, 2.0), (7.0, 1.4, 1.6)])
def test_clears_the_danger_zone(table: MaxSteeringTable, v: float, tau: float, w: float) -> None:
    path = closed_loop_on_kinematics(table, v, tau, w)
    x_min = v * tau
    beside = path[(path[:, 0] >= x_min - 0.5) & (path[:, 0] <= x_min + 2.5)]
    assert len(beside) and np.all(beside[:, 1] > w)
    assert abs(path[-1, 1]) < 0.5 * np.max(path[:, 1])  # returning to the lane


def test_mirror(table: MaxSteeringTable) -> None:
    left = closed_loop_on_kinematics(table, 6.0, 3.0, 2.0, side=1)
    right = closed_loop_on_kinematics(table, 6.0, 3.0, 2.0, side=-1)
    np.testing.assert_allclose(left[:, 1], -right[:, 1], atol=1e-9)


def test_idle_keeps_the_lane_and_speed(table: MaxSteeringTable) -> None:
    planner = MsfPlanner(MsfParams(), table, VEHICLE)
    plan = planner.plan(PlannerInput(0.0, StateEstimate(0.0, 0.0, 0.8, 0.0, 5.0, 0.0, 0.0, 0.0), None, 6.0, None))
    assert plan.status == "idle"
    assert plan.accel[0, 1] < 0.0 and plan.accel[0, 0] > 0.0
