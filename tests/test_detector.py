"""Obstacle detector (Sec. III): tau, w, side, nu with hand-computed numbers; latching and clearing."""
from __future__ import annotations

import math

import pytest

from moose.detector import ObstacleDetector
from moose.maneuver import MaxSteeringTable
from moose.paper import PAPER_FRICTION
from moose.params import ParamError, VehicleParams
from moose.schema import DetectorParams, ManeuverParams
from moose.signals import Obstacle, StateEstimate

VEHICLE = VehicleParams(mu=PAPER_FRICTION)  # the friction of the paper's nu


@pytest.fixture(scope="module")
def table() -> MaxSteeringTable:
    return MaxSteeringTable.build(VEHICLE, ManeuverParams())


def est(x: float, y: float, vx: float = 6.0, t: float = 0.0) -> StateEstimate:
    return StateEstimate(t, x, y, 0.0, vx, 0.0, 0.0, 0.0)


def test_measures_of_a_centred_zone(table: MaxSteeringTable) -> None:
    detector = ObstacleDetector(DetectorParams(), table)
    zone = Obstacle(19.0, 21.0, -2.0, 2.6)
    threat = detector.update(0.0, est(1.0, 0.3), [zone])
    assert threat is not None
    assert threat.tau == pytest.approx(3.0)  # (19 - 1) / 6
    assert threat.side == 1 and threat.w == pytest.approx(2.3)  # 2.6 - 0.3 on both sides: tie -> left
    assert threat.y_path == 0.3 and threat.obstacle == zone and threat.t == 0.0
    assert threat.nu == pytest.approx(2.3 / table.y_max(3.0, 6.0))
    assert 0.2 < threat.nu < 0.35  # the paper's 6 m/s, tau = 3 s cases: nu = 0.21 .. 0.34


def test_paper_extreme_case_nu(table: MaxSteeringTable) -> None:
    # 7 m/s, tau = 1.4 s, w = 2.0 m: the paper prints nu = 0.95
    threat = ObstacleDetector(DetectorParams(), table).update(0.0, est(0.0, 0.0, 7.0), [Obstacle(9.8, 11.8, -2.0, 2.0)])
    assert threat is not None and threat.tau == pytest.approx(1.4) and threat.w == 2.0
    assert threat.nu == pytest.approx(0.95, abs=0.05)


def test_smaller_displacement_side_and_the_tie_band(table: MaxSteeringTable) -> None:
    # right edge 0.5 m away, left edge 3 m away: evade right by w = 0.5
    threat = ObstacleDetector(DetectorParams(), table).update(0.0, est(0.0, 0.0), [Obstacle(20.0, 22.0, -0.5, 3.0)])
    assert threat is not None and threat.side == -1 and threat.w == pytest.approx(0.5)
    # left needs 0.2 m more than right: within the 0.25 m tie band -> left
    threat = ObstacleDetector(DetectorParams(), table).update(0.0, est(0.0, 0.0), [Obstacle(20.0, 22.0, -2.0, 2.2)])
    assert threat is not None and threat.side == 1 and threat.w == pytest.approx(2.2)
    # 0.3 m more: right, w = 2.0
    threat = ObstacleDetector(DetectorParams(), table).update(0.0, est(0.0, 0.0), [Obstacle(20.0, 22.0, -2.0, 2.3)])
    assert threat is not None and threat.side == -1 and threat.w == pytest.approx(2.0)
    # no tie band: the strictly smaller side
    threat = ObstacleDetector(DetectorParams(side_tie=0.0), table).update(
        0.0, est(0.0, 0.0), [Obstacle(20.0, 22.0, -2.0, 2.2)])
    assert threat is not None and threat.side == -1


def test_mirror(table: MaxSteeringTable) -> None:
    left = ObstacleDetector(DetectorParams(), table).update(0.0, est(2.0, 0.4), [Obstacle(20.0, 22.0, -3.0, 1.5)])
    right = ObstacleDetector(DetectorParams(), table).update(0.0, est(2.0, -0.4), [Obstacle(20.0, 22.0, -1.5, 3.0)])
    assert left is not None and right is not None
    assert (left.side, right.side) == (1, -1)
    assert left.w == pytest.approx(right.w) == pytest.approx(1.1)
    assert left.tau == right.tau and left.nu == right.nu
    assert right.y_path == -left.y_path


def test_path_and_side_are_latched_and_the_threat_clears_after_passing(table: MaxSteeringTable) -> None:
    detector = ObstacleDetector(DetectorParams(pass_margin=2.0), table)
    zone = Obstacle(19.0, 21.0, -2.0, 2.0)
    first = detector.update(0.0, est(1.0, 0.0), [zone])
    assert first is not None and first.side == 1 and first.w == 2.0
    # the car moved 2.5 m left: now the left edge is nearer, but side, path and w stay
    moved = detector.update(2.0, est(13.0, 2.5, t=2.0), [zone])
    assert moved is not None and (moved.side, moved.y_path, moved.w) == (1, 0.0, 2.0)
    assert moved.tau == pytest.approx(1.0)
    # beside the zone: tau <= 0, nu infinite (no lateral motion possible any more), still reported
    beside = detector.update(3.2, est(20.5, 2.6, t=3.2), [zone])
    assert beside is not None and beside.tau == pytest.approx(-0.25) and beside.nu == math.inf
    assert detector.update(3.4, est(22.9, 2.6, t=3.4), [zone]) is not None  # 1.9 m past x_max
    assert detector.update(3.5, est(23.1, 2.6, t=3.5), [zone]) is None  # 2.1 m past x_max
    assert detector.update(3.6, est(23.2, 0.5, t=3.6), [zone]) is None  # and stays cleared


def test_zone_not_in_the_path_out_of_range_or_not_visible(table: MaxSteeringTable) -> None:
    beside_path = Obstacle(20.0, 22.0, 0.5, 3.0)
    assert ObstacleDetector(DetectorParams(), table).update(0.0, est(0.0, 0.0), [beside_path]) is None
    # within a lateral margin it counts, and needs no displacement: w = 0, nu = 0 (evade right)
    threat = ObstacleDetector(DetectorParams(lateral_margin=0.6), table).update(0.0, est(0.0, 0.0), [beside_path])
    assert threat is not None and threat.side == -1 and threat.w == 0.0 and threat.nu == 0.0
    far = Obstacle(90.0, 92.0, -2.0, 2.0)
    assert ObstacleDetector(DetectorParams(range_m=80.0), table).update(0.0, est(0.0, 0.0), [far]) is None
    detector = ObstacleDetector(DetectorParams(), table)
    zone = Obstacle(20.0, 22.0, -2.0, 2.0)
    assert detector.update(0.0, est(0.0, 0.0), [zone]) is not None
    assert detector.update(0.1, est(0.6, 0.5), []) is None  # the sensor lost it
    again = detector.update(0.2, est(1.2, 0.5), [zone])  # seen again: a new detection, path latched anew
    assert again is not None and again.y_path == 0.5 and again.w == pytest.approx(1.5)


def test_nearest_zone_in_the_path_is_reported(table: MaxSteeringTable) -> None:
    detector = ObstacleDetector(DetectorParams(), table)
    near, far = Obstacle(12.0, 14.0, -1.0, 1.0), Obstacle(30.0, 32.0, -2.0, 2.0)
    threat = detector.update(0.0, est(0.0, 0.0), [far, near])
    assert threat is not None and threat.obstacle == near and threat.tau == pytest.approx(2.0)
    # once the near one is passed, the far one is next
    threat = detector.update(3.0, est(17.0, 0.0, t=3.0), [far, near])
    assert threat is not None and threat.obstacle == far and threat.tau == pytest.approx(13.0 / 6.0)


def test_standstill_is_no_collision_course(table: MaxSteeringTable) -> None:
    threat = ObstacleDetector(DetectorParams(), table).update(0.0, est(0.0, 0.0, vx=0.0),
                                                              [Obstacle(20.0, 22.0, -1.0, 1.0)])
    assert threat is not None and threat.tau == math.inf and threat.w == 1.0 and threat.nu == 0.0


@pytest.mark.parametrize("field", ["pass_margin", "range_m", "side_tie", "lateral_margin"])
def test_bad_parameters_name_the_field(field: str) -> None:
    with pytest.raises(ParamError, match=field):
        DetectorParams(**{field: -1.0})
