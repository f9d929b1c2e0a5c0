"""Verdicts from sampled ground truth: every outcome on hand-made traces with known answers."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from moose.schema import VerdictParams
from moose.signals import Obstacle
from moose.verdict import judge, segment_hits_box

ZONE = Obstacle(20.0, 22.0, -2.0, 2.0)
FIELD = Obstacle(-50.0, 150.0, -5.0, 10.0)
END = 8.0


def straight(y: float = 3.0, v: float = 6.0, dt: float = 0.01, end: float = END, x0: float = 0.0) -> dict[str, np.ndarray]:
    t = np.arange(0.0, end + 1e-9, dt)
    return {"t": t, "x": x0 + v * t, "y": np.full_like(t, y), "theta": np.zeros_like(t), "vx": np.full_like(t, v),
            "vy": np.zeros_like(t)}


def verdict(tr: dict[str, np.ndarray], params: VerdictParams = VerdictParams()):
    return judge(tr["t"], tr["x"], tr["y"], tr["theta"], tr["vx"], tr["vy"], ZONE, FIELD, END, params)


def test_a_car_beside_the_zone_clears_it_by_the_lateral_gap() -> None:
    v = verdict(straight(y=3.0))
    assert v.outcome == "clear" and v.complete and v.passed_obstacle
    assert v.min_clearance_m == pytest.approx(1.0)  # 3.0 - y_max 2.0: the near side, not the far one
    assert v.max_abs_sideslip_rad == 0.0 and v.max_abs_heading_rad == 0.0


def test_a_car_through_the_middle_of_the_zone_collides() -> None:
    v = verdict(straight(y=0.0))
    assert v.outcome == "collision" and v.collided
    assert v.min_clearance_m == pytest.approx(-1.0)  # 1 m from either long edge: deepest inside is -1


def test_a_corner_cut_between_two_samples_is_a_collision() -> None:
    # 1 s samples: no sample is inside, but the straight segment between two crosses the corner
    t = np.array([0.0, 1.0, 2.0])
    x, y = np.array([15.0, 19.0, 23.0]), np.array([-1.0, -1.0, -1.0])
    assert np.all(ZONE.clearance(x, y) > 0.0)  # every sample outside: before and after the zone
    assert segment_hits_box(19.0, -1.0, 23.0, -1.0, ZONE)
    tr = {"t": t * 4.0, "x": x, "y": y, "theta": np.zeros(3), "vx": np.ones(3), "vy": np.zeros(3)}
    v = judge(tr["t"], tr["x"], tr["y"], tr["theta"], tr["vx"], tr["vy"], ZONE, FIELD, 8.0, VerdictParams(max_gap=5.0))
    assert v.outcome == "collision" and v.min_clearance_m == 0.0
    assert not segment_hits_box(0.0, 3.0, 40.0, 3.0, ZONE) and segment_hits_box(21.0, 5.0, 21.0, -5.0, ZONE)


def test_leaving_the_field_is_reported_with_where() -> None:
    tr = straight(y=3.0)
    tr["y"] = np.where(tr["t"] > 6.0, 11.0, 3.0)
    v = verdict(tr)
    assert v.outcome == "left_field" and v.left_field and "(" in v.reason


@pytest.mark.parametrize("beta, expected", [(0.34, "clear"), (0.36, "lost_control")])
def test_sideslip_beyond_the_threshold_is_lost_control(beta: float, expected: str) -> None:
    tr = straight(y=3.0)
    tr["vx"], tr["vy"] = 6.0 * np.cos(beta) * np.ones_like(tr["t"]), 6.0 * np.sin(beta) * np.ones_like(tr["t"])
    v = verdict(tr)
    assert v.outcome == expected and v.max_abs_sideslip_rad == pytest.approx(beta)


def test_sideslip_at_a_crawl_is_not_judged_but_heading_is() -> None:
    tr = straight(y=3.0)
    slow = tr["t"] > 6.0
    tr["vx"] = np.where(slow, 0.1, 6.0)
    tr["vy"] = np.where(slow, 1.0, 0.0)  # atan2 = 1.47 rad, but at 1 m/s: not a sideslip verdict
    assert verdict(tr).outcome == "clear"
    tr["theta"] = np.where(slow, 1.7, 0.0)  # turned across the road
    v = verdict(tr)
    assert v.outcome == "lost_control" and "heading" in v.reason


def test_a_car_that_stops_before_the_obstacle_stopped_short() -> None:
    tr = straight(y=0.0, v=2.0)  # reaches x = 16 m by 8 s: never at the zone
    v = verdict(tr)
    assert v.outcome == "stopped_short" and not v.passed_obstacle and v.min_clearance_m == pytest.approx(4.0)


@pytest.mark.parametrize("cut", ["none", "late_start", "early_end", "gap"])
def test_runs_that_do_not_cover_the_time_are_incomplete(cut: str) -> None:
    tr = straight(y=3.0)
    keep = {"none": np.zeros_like(tr["t"], dtype=bool), "late_start": tr["t"] > 0.5,
            "early_end": tr["t"] < 2.6, "gap": (tr["t"] < 3.0) | (tr["t"] > 3.5)}[cut]
    v = verdict({k: a[keep] for k, a in tr.items()})
    assert v.outcome == "incomplete" and not v.complete and v.reason


def test_a_collision_in_an_incomplete_run_is_still_a_collision() -> None:
    tr = straight(y=0.0, v=10.0)  # through the zone at 2 s, then the data stops
    keep = tr["t"] < 3.0
    assert verdict({k: a[keep] for k, a in tr.items()}).outcome == "collision"


def test_non_finite_samples_count_as_missing() -> None:
    tr = straight(y=3.0)
    tr["x"][300:400] = np.nan  # 1 s of NaN: a gap
    assert verdict(tr).outcome == "incomplete"


def test_summary_json_is_strict_json() -> None:
    from moose.config import load_config
    from moose.metrics import summarize
    from moose.scenario import adhoc_scenario
    from moose.simulation import simulate

    # the obstacle 0.1 s ahead at 7 m/s: nu is infinite for the detector (no reach in time)
    s = summarize(simulate(load_config(), adhoc_scenario(7.0, 0.05, 1.0, duration=1.0)))
    text = json.dumps(s, allow_nan=False)  # raises on NaN or Infinity
    back = json.loads(text)
    for key, value in back.items():
        if isinstance(value, float):
            assert math.isfinite(value), key
    if back["nu"] is None:
        assert back["notes"]["nu"]
