"""The planners behind one protocol (moose.planner.Planner): after ``reset`` a planner plans as a new one."""
from __future__ import annotations

import numpy as np
import pytest

from moose.config import load_config
from moose.planner import Planner
from moose.planner.step import PlanningStep
from moose.signals import Obstacle, PlannerInput, StateEstimate, Threat

CONFIG = load_config()
THREAT = Threat(0.0, Obstacle(12.0, 14.0, -0.5, 2.0), 12.0 / 7.0, 2.0, 0.5, 1, 0.0)
EVADING = PlannerInput(0.0, StateEstimate(0.0, 0.0, 0.0, 0.0, 7.0, 0.0, 0.0, 0.0), THREAT, 7.0, None)
PAST = PlannerInput(2.4, StateEstimate(2.4, 17.0, 2.3, 0.05, 7.0, 0.1, 0.0, 0.0), None, 7.0, None)
"""2.4 s later, past the obstacle and out to the side: the threat has cleared."""


def planner(name: str) -> Planner:
    """The MPC or MSF planner of the combined mode, or a baseline (in the MSF planner's slot of its mode)."""
    built = PlanningStep(CONFIG, "combined").mpc if name == "mpc" else PlanningStep(CONFIG, name).msf
    assert built is not None
    return built


@pytest.mark.parametrize("name", ["mpc", "msf", "aeb", "max_steer"])
def test_after_reset_a_planner_plans_as_a_new_one(name: str) -> None:
    used, new = planner(name), planner(name)
    used.plan(EVADING)
    used.reset()
    after, fresh = used.plan(PAST), new.plan(PAST)
    assert after.status == fresh.status
    np.testing.assert_array_equal(after.accel, fresh.accel)
    np.testing.assert_array_equal(after.predicted, fresh.predicted)


def test_without_reset_the_msf_planner_flies_back_from_its_evasion() -> None:
    """What ``reset`` forgets: the evasion under way, whose end starts the return to the lane."""
    used, new = planner("msf"), planner("msf")
    used.plan(EVADING)
    assert not np.allclose(used.plan(PAST).accel, new.plan(PAST).accel, atol=1e-3)
