"""y_max (eq. (ymax)) against the paper's own fit and its printed nu values; tau and nu."""
from __future__ import annotations

import math

import numpy as np
import pytest

from moose.maneuver import (
    ManeuverParams, MaxSteeringTable, integrate_y_max, lateral_steering_index, paper_y_max_fit, time_to_collision,
)
from moose.params import VehicleParams

VEHICLE = VehicleParams()


@pytest.fixture(scope="module")
def table() -> MaxSteeringTable:
    return MaxSteeringTable.build(VEHICLE, ManeuverParams())


def test_default_friction_reproduces_the_paper_fit(table: MaxSteeringTable) -> None:
    # The fit is a quartic through the paper's curves; it goes negative near t = 0,
    # so we compare where it is meaningful: t in [1, 5] s, the speeds of the experiments.
    errors = [table.y_max(t, v) - paper_y_max_fit(v, t) for v in (3, 4, 5, 6, 7) for t in np.arange(1.0, 5.01, 0.5)]
    assert math.sqrt(np.mean(np.square(errors))) < 2.0
    # and clearly better than a dry-road friction would
    dry = MaxSteeringTable.build(VEHICLE, ManeuverParams(mu_ymax=1.0))
    errors_dry = [dry.y_max(t, v) - paper_y_max_fit(v, t) for v in (3, 4, 5, 6, 7) for t in np.arange(1.0, 5.01, 0.5)]
    assert math.sqrt(np.mean(np.square(errors_dry))) > 2.0 * math.sqrt(np.mean(np.square(errors)))


NINE = [(5, 5, 4.0, 0.25), (5, 4, 3.2, 0.26), (5, 3, 2.4, 0.32), (6, 3, 2.0, 0.21), (6, 3, 2.4, 0.26),
        (4.5, 3, 3.2, 0.34), (7, 2.8, 2.0, 0.19), (7, 2, 2.0, 0.40), (7, 1.4, 2.0, 0.95)]


@pytest.mark.parametrize("v, tau, w, nu", NINE)
def test_nu_of_the_nine_experiments(table: MaxSteeringTable, v: float, tau: float, w: float, nu: float) -> None:
    assert lateral_steering_index(w, tau, v, table) == pytest.approx(nu, abs=0.05 + 0.12 * nu)


def test_monotonic_and_zero_at_start(table: MaxSteeringTable) -> None:
    for v in (3.0, 5.0, 7.0):
        ys = [table.y_max(t, v) for t in np.arange(0.0, 5.0, 0.05)]
        assert ys[0] == 0.0
        assert np.all(np.diff(ys) >= -1e-9)


def test_interpolation_matches_direct_integration(table: MaxSteeringTable) -> None:
    v = np.array([5.37, 6.81])
    t, y, vY, _ = integrate_y_max(VEHICLE, table.mu, v, 3.0, 1e-3)
    for k in (437, 1291, 2763):
        for j in range(2):
            assert table.y_max(t[k], v[j]) == pytest.approx(y[k, j], abs=0.02)
            assert table.v_Y_max(t[k], v[j]) == pytest.approx(vY[k, j], abs=0.02)


def test_lateral_acceleration_is_the_derivative_of_lateral_speed(table: MaxSteeringTable) -> None:
    for t in (0.5, 1.5, 3.0):
        numeric = (table.v_Y_max(t + 0.05, 6.0) - table.v_Y_max(t - 0.05, 6.0)) / 0.1
        assert table.a_Y_max(t, 6.0) == pytest.approx(numeric, abs=0.05)


def test_tau_and_nu_edge_cases(table: MaxSteeringTable) -> None:
    assert time_to_collision(14.0, 7.0) == 2.0
    assert time_to_collision(14.0, 0.0) == math.inf
    assert lateral_steering_index(2.0, 0.0, 7.0, table) == math.inf
    assert lateral_steering_index(2.0, 3.0, 7.0, table) < lateral_steering_index(2.0, 1.5, 7.0, table)
