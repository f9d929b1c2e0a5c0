"""The danger-zone geometry and the estimate's derived quantities, against independent formulas.

Clearance reference: outside a box the distance to it is the distance to the nearest point of the box,
(x − clip(x, x_min, x_max), y − clip(y, y_min, y_max)); inside, minus the distance to the nearest of
the four edges.  Neither is how :meth:`Obstacle.clearance` computes it.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from moose.params import ParamError
from moose.signals import Obstacle, StateEstimate

ZONE = Obstacle(20.0, 22.0, -2.0, 2.0)
coordinate = st.floats(-60.0, 60.0, allow_nan=False)


def reference_clearance(box: Obstacle, x: float, y: float) -> float:
    inside = box.x_min <= x <= box.x_max and box.y_min <= y <= box.y_max
    if inside:
        return -min(x - box.x_min, box.x_max - x, y - box.y_min, box.y_max - y)
    return math.hypot(x - min(max(x, box.x_min), box.x_max), y - min(max(y, box.y_min), box.y_max))


@pytest.mark.parametrize("x, y, expected", [
    (21.0, 0.0, -1.0),  # the middle: 1 m from both long edges (the far edge is 3 m away, the near one 1 m)
    (21.0, 1.5, -0.5),  # nearer the left edge y_max
    (21.0, -1.8, -0.2),  # nearer the right edge y_min
    (20.1, 0.0, -0.1),  # just past the near end
    (21.9, 0.3, -0.1),  # just before the far end
    (21.0, 3.0, 1.0),  # beside the zone on the left: the lateral gap to y_max, not to y_min (5 m)
    (21.0, -2.5, 0.5),  # beside it on the right
    (18.0, 0.0, 2.0),  # ahead of it
    (25.0, 1.0, 3.0),  # behind it
    (17.0, 6.0, 5.0),  # diagonal to the corner (20, 2): a 3-4-5 triangle
    (25.0, -6.0, 5.0),  # diagonal to the corner (22, -2)
    (20.0, 2.0, 0.0),  # on a corner
    (21.0, 2.0, 0.0),  # on an edge
])
def test_clearance_of_points_with_known_answers(x: float, y: float, expected: float) -> None:
    assert ZONE.clearance(x, y) == pytest.approx(expected, abs=1e-12)
    assert isinstance(ZONE.clearance(x, y), float)
    assert ZONE.contains(x, y) == (expected <= 0.0)


@settings(max_examples=300, deadline=None)
@given(coordinate, coordinate, coordinate, coordinate, st.floats(0.01, 30.0), st.floats(0.01, 30.0))
def test_clearance_equals_the_independent_formula(x: float, y: float, x0: float, y0: float, length: float,
                                                  width: float) -> None:
    box = Obstacle(x0, x0 + length, y0, y0 + width)
    assert box.clearance(x, y) == pytest.approx(reference_clearance(box, x, y), abs=1e-9)
    assert box.contains(x, y) == (box.x_min <= x <= box.x_max and box.y_min <= y <= box.y_max)


def test_clearance_is_computed_in_double_precision() -> None:
    box = Obstacle(0.1, 0.2, 0.1, 0.2)  # edges single precision cannot hold
    x, y = np.float32(5.3), np.float32(7.7)  # single-precision positions (a float32 log): exact in double
    expected = math.hypot(float(x) - 0.2, float(y) - 0.2)
    for xs, ys in ((x, y), (np.array([x]), np.array([y]))):
        assert float(np.ravel(box.clearance(xs, ys))[0]) == pytest.approx(expected, rel=1e-14, abs=0.0)
        assert float(np.ravel(box.clearance(xs, float(y)))[0]) == pytest.approx(expected, rel=1e-14, abs=0.0)
        assert float(np.ravel(box.clearance(float(x), ys))[0]) == pytest.approx(expected, rel=1e-14, abs=0.0)
    assert box.clearance(np.array([x]), np.array([y])).dtype == np.float64
    assert ZONE.clearance(17, 6) == 5.0 and ZONE.clearance([17], [6]).dtype == np.float64  # integers too


def test_clearance_of_arrays_is_elementwise() -> None:
    xs = np.array([21.0, 21.0, 18.0, 17.0])
    ys = np.array([0.0, 3.0, 0.0, 6.0])
    gaps = ZONE.clearance(xs, ys)
    assert isinstance(gaps, np.ndarray) and gaps.shape == (4,)
    assert gaps == pytest.approx([-1.0, 1.0, 2.0, 5.0])


def test_contains_is_closed_and_tight() -> None:
    eps = 1e-9
    for x, y in ((20.0, 0.0), (22.0, 0.0), (21.0, -2.0), (21.0, 2.0)):
        assert ZONE.contains(x, y)
    for x, y in ((20.0 - eps, 0.0), (22.0 + eps, 0.0), (21.0, -2.0 - eps), (21.0, 2.0 + eps)):
        assert not ZONE.contains(x, y)


@pytest.mark.parametrize("bounds, field", [((1.0, 1.0, 0.0, 1.0), "x_min"), ((2.0, 1.0, 0.0, 1.0), "x_min"),
                                           ((0.0, 1.0, 1.0, 1.0), "y_min"), ((0.0, 1.0, 3.0, -1.0), "y_min")])
def test_an_empty_or_inverted_box_is_refused(bounds: tuple, field: str) -> None:
    with pytest.raises(ParamError, match=f"^{field} = "):
        Obstacle(*bounds)


@given(st.floats(-20.0, 20.0), st.floats(-5.0, 5.0), st.floats(-math.pi, math.pi))
def test_global_velocity_is_the_body_velocity_rotated_by_the_yaw(vx: float, vy: float, theta: float) -> None:
    e = StateEstimate(t=0.0, x=0.0, y=0.0, theta=theta, vx=vx, vy=vy, gamma=0.0, delta=0.0)
    # rotating back by −θ recovers the body velocity; the speed is kept
    assert e.vX * math.cos(theta) + e.vY * math.sin(theta) == pytest.approx(vx, abs=1e-9)
    assert -e.vX * math.sin(theta) + e.vY * math.cos(theta) == pytest.approx(vy, abs=1e-9)
    assert math.hypot(e.vX, e.vY) == pytest.approx(math.hypot(vx, vy), abs=1e-9)


def test_velocity_directions_follow_rep_103() -> None:
    left = StateEstimate(t=0.0, x=0.0, y=0.0, theta=math.pi / 2, vx=3.0, vy=0.0, gamma=0.0, delta=0.0)
    assert left.vX == pytest.approx(0.0, abs=1e-12) and left.vY == pytest.approx(3.0)  # heading +90°: moving to +y
    sliding = StateEstimate(t=0.0, x=0.0, y=0.0, theta=0.0, vx=0.0, vy=2.0, gamma=0.0, delta=0.0)
    assert sliding.vY == pytest.approx(2.0) and sliding.vX == pytest.approx(0.0)  # body +y is the left


@pytest.mark.parametrize("vx, vy, beta", [(5.0, 0.5, math.atan(0.1)), (5.0, -0.5, -math.atan(0.1)),
                                          (-2.0, 1.0, math.atan2(1.0, -2.0)), (1e-7, 1.0, 0.0), (0.0, 0.0, 0.0),
                                          (-1e-7, 1.0, 0.0), (2e-6, 1e-6, math.atan(0.5))])
def test_sideslip_angle(vx: float, vy: float, beta: float) -> None:
    e = StateEstimate(t=0.0, x=0.0, y=0.0, theta=0.3, vx=vx, vy=vy, gamma=0.0, delta=0.0)
    assert e.beta == pytest.approx(beta, abs=1e-12)


def test_time_to_collision_at_its_edges() -> None:
    """τ = distance / v_x while the car closes in (v_x above 1e-9 m/s, however slowly); at a standstill, infinite
    before the obstacle and 0 at or past it."""
    from moose.signals import time_to_collision

    assert time_to_collision(10.0, 5.0) == 2.0
    assert time_to_collision(10.0, 0.5) == 20.0
    assert time_to_collision(10.0, 1e-9) == math.inf  # not closing in
    assert time_to_collision(0.5, 0.0) == math.inf
    assert time_to_collision(0.0, 0.0) == 0.0
    assert time_to_collision(-1.0, 0.0) == 0.0
    assert time_to_collision(-1.0, 2.0) == -0.5  # the near edge behind the CoG
