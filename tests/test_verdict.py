"""Verdicts from sampled ground truth: every outcome on hand-made traces with known answers."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from moose.schema import VerdictParams
from moose.signals import Obstacle
from moose.verdict import judge, segment_hits_box

ZONE = Obstacle(20.0, 22.0, -2.0, 2.0)
FIELD = Obstacle(-50.0, 150.0, -5.0, 10.0)
END = 8.0
VERDICT = VerdictParams()


def straight(y: float = 3.0, v: float = 6.0, dt: float = 0.01, end: float = END,
             x0: float = 0.0) -> dict[str, np.ndarray]:
    t = np.arange(0.0, end + 1e-9, dt)
    return {"t": t, "x": x0 + v * t, "y": np.full_like(t, y), "theta": np.zeros_like(t), "vx": np.full_like(t, v),
            "vy": np.zeros_like(t)}


def verdict(tr: dict[str, np.ndarray], params: VerdictParams = VERDICT):
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


def test_a_run_judged_with_other_limits_says_so(tmp_path, capsys) -> None:
    """The probe: ``moose simulate --planner mpc --set verdict.sideslip_max=10`` printed "CLEAR … in control",
    rc 0, where the default verdict is LOST_CONTROL (|β| 0.39 rad), and the summary did not say that its limits
    were changed.  The summary records them; the printed verdict names the changed one."""
    from moose.cli import main

    paths = {}
    for label, extra in (("default", []), ("loose", ["--set", "verdict.sideslip_max=10"])):
        paths[label] = tmp_path / f"{label}.json"
        main(["simulate", "--planner", "mpc", "--no-bag", "--json", str(paths[label]), *extra])
        printed = capsys.readouterr().out
        outcome = next(line for line in printed.splitlines() if line.startswith("outcome"))
        if label == "loose":
            assert "under NON-DEFAULT verdict limits (sideslip_max = 10 instead of 0.35)" in outcome, outcome
        else:
            assert "NON-DEFAULT" not in outcome, outcome
    default, loose = (json.loads(paths[k].read_text()) for k in ("default", "loose"))
    assert default["verdict_limits_default"] is True and loose["verdict_limits_default"] is False
    assert default["verdict_limits"] == {"sideslip_max": 0.35, "sideslip_speed_min": 2.0, "heading_max": math.pi / 2,
                                         "max_gap": 0.2}
    assert loose["verdict_limits"] == {**default["verdict_limits"], "sideslip_max": 10.0}
    assert default["outcome"] == "lost_control" and loose["outcome"] == "clear"  # the same run, judged twice


def test_the_claims_table_is_judged_with_the_default_limits(tmp_path) -> None:
    """``moose reproduce`` refuses a configuration with other verdict limits before any run."""
    import subprocess
    import sys

    from moose.config import load_config, with_overrides
    from moose.params import ParamError
    from moose.reproduce import RunCache

    config = with_overrides(load_config(), {"verdict.heading_max": 3.0})
    with pytest.raises(ParamError, match="heading_max = 3 instead of 1.5708: the paper's claims are judged with the "
                                         "default verdict limits"):
        RunCache(config)
    path = tmp_path / "loose.yaml"
    path.write_text("/**:\n  ros__parameters:\n    verdict: {sideslip_max: 10.0}\n")
    out = subprocess.run([sys.executable, "-m", "moose.cli", "reproduce", "--config", str(path)], capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 2 and "moose: error: verdict: sideslip_max = 10 instead of 0.35" in out.stderr, out.stderr
    assert RunCache(load_config()).run("paper_v5_tau3").summary["verdict_limits_default"]


# -- boundaries, reasons and flags: each threshold is inclusive on the documented side

DEFAULT_PARAMS = VerdictParams()


def run(t, x, y, theta=None, vx=None, vy=None, end: float = END, params: VerdictParams = DEFAULT_PARAMS):
    t = np.asarray(t, dtype=float)
    zeros = np.zeros_like(t)
    return judge(t, x, y, zeros if theta is None else theta, np.full_like(t, 6.0) if vx is None else vx,
                 zeros if vy is None else vy, ZONE, FIELD, end, params)


def test_no_samples_at_all() -> None:
    from moose.verdict import Verdict

    v = run([], [], [])
    assert v == Verdict("incomplete", False, False, False, False, False, None, None, None,
                        "no samples of the vehicle state")


def test_coverage_boundaries_and_reasons() -> None:
    p = VerdictParams(max_gap=0.25)
    t = np.arange(0.0, 8.0 + 1e-9, 0.25)  # exact binary fractions: every gap is exactly max_gap
    x, y = 6.0 * t, np.full_like(t, 3.0)
    assert run(t, x, y, params=p).outcome == "clear"  # gaps of exactly max_gap, first at 0, last at the end
    assert run(t + 0.25, x, y, params=p).outcome == "clear"  # first sample exactly max_gap after the start
    assert run(t[:-1], x[:-1], y[:-1], params=p).outcome == "clear"  # last one exactly max_gap before the end
    late = run(t[2:], x[2:], y[2:], params=p)
    assert late.outcome == "incomplete" and late.reason == "first sample at t = 0.50 s (allowed gap 0.25 s)"
    early = run(t[:-2], x[:-2], y[:-2], params=p)
    assert early.reason == "samples end at t = 7.50 s, the run was to end at 8.00 s"
    keep = (t < 3.0) | (t > 3.5)
    gap = run(t[keep], x[keep], y[keep], params=p)
    assert gap.reason == "no sample between t = 2.75 s and 3.75 s (allowed gap 0.25 s)"
    second = np.concatenate([[0.0], t[2:]])  # a first sample in time, then a gap: the gap is the reason
    v = run(second, 6.0 * second, np.full_like(second, 3.0), params=p)
    assert v.reason == "no sample between t = 0.00 s and 0.50 s (allowed gap 0.25 s)"


def test_sideslip_and_heading_limits_are_exclusive_and_speed_limit_inclusive() -> None:
    t = np.arange(0.0, END + 1e-9, 0.01)
    x, y = 6.0 * t, np.full_like(t, 3.0)
    # exactly 2 m/s (1.2, 1.6): judged, and far beyond the limit
    v = run(t, x, y, vx=np.full_like(t, 1.2), vy=np.full_like(t, 1.6))
    assert v.outcome == "lost_control" and v.lost_control
    assert v.max_abs_sideslip_rad == pytest.approx(math.atan2(1.6, 1.2))
    assert v.reason == f"|sideslip| reached {math.atan2(1.6, 1.2):.2f} rad (limit 0.35)"
    beta = float(np.arctan2(0.5, 6.0))
    at_limit = run(t, x, y, vy=np.full_like(t, 0.5), params=VerdictParams(sideslip_max=beta))
    assert at_limit.outcome == "clear" and not at_limit.lost_control
    heading = run(t, x, y, theta=np.full_like(t, 1.0), params=VerdictParams(heading_max=1.0))
    assert heading.outcome == "clear" and heading.max_abs_heading_rad == 1.0
    turned = run(t, x, y, theta=np.where(t > 5.0, -1.6, 0.0))
    assert turned.outcome == "lost_control" and turned.lost_control and turned.max_abs_heading_rad == 1.6
    assert turned.reason == "|heading| reached 1.60 rad (limit 1.57)"
    slow = run(t, x, y, vx=np.full_like(t, 0.5), vy=np.zeros_like(t))
    assert slow.max_abs_sideslip_rad is None  # never fast enough to judge β


def test_field_edges_belong_to_the_field_and_the_reason_says_where_it_was_left() -> None:
    t = np.arange(0.0, END + 1e-9, 0.01)
    for x0, y0 in ((FIELD.x_min, 3.0), (FIELD.x_max, 3.0), (30.0, FIELD.y_min), (30.0, FIELD.y_max)):
        # a car standing on an edge of the field the whole run: inside (stopped short or clear, never left_field)
        v = run(t, np.full_like(t, x0), np.full_like(t, y0), vx=np.zeros_like(t))
        assert not v.left_field and v.outcome in ("stopped_short", "clear"), (x0, y0)
    y = np.where(t >= 6.0, 10.5, 3.0)
    v = run(t, 6.0 * t, y)
    assert v.outcome == "left_field" and v.left_field
    assert v.reason == "the CoG left the field at t = 6.00 s, (36.0, 10.5) m"


def test_passing_means_beyond_the_far_edge() -> None:
    t = np.arange(0.0, END + 1e-9, 0.01)
    y = np.full_like(t, 3.0)
    at_edge = run(t, np.minimum(6.0 * t, ZONE.x_max), y)
    assert at_edge.outcome == "stopped_short" and not at_edge.passed_obstacle
    assert at_edge.reason == "the CoG never passed the zone's far edge x = 22 m (reached 22.00 m)"
    passed = run(t, np.minimum(6.0 * t, ZONE.x_max + 0.01), y)
    assert passed.outcome == "clear" and passed.passed_obstacle
    assert passed.reason == "passed with 1.00 m clearance, in control, inside the field"


def test_a_pass_closer_than_a_metre_is_clear_and_a_touch_is_a_collision() -> None:
    t = np.arange(0.0, END + 1e-9, 0.01)
    close = run(t, 6.0 * t, np.full_like(t, ZONE.y_max + 0.3))
    assert close.outcome == "clear" and close.min_clearance_m == pytest.approx(0.3)
    grazing = run(t, 6.0 * t, np.full_like(t, ZONE.y_max))  # along the edge: touching the closed zone
    assert grazing.outcome == "collision" and grazing.min_clearance_m == 0.0
    assert grazing.reason == "the CoG path enters the danger zone (min clearance 0.00 m)"
    # one sample, on the edge: no segment to check, the sample itself touches
    single = judge(np.array([0.0]), np.array([ZONE.x_min]), np.array([0.0]), np.zeros(1), np.ones(1), np.zeros(1),
                   ZONE, FIELD, 0.1)
    assert single.collided and single.outcome == "collision"
    inside = judge(np.array([0.0]), np.array([21.0]), np.array([0.5]), np.zeros(1), np.ones(1), np.zeros(1),
                   ZONE, FIELD, 0.1)
    assert inside.collided and inside.min_clearance_m == pytest.approx(-1.0)


def test_a_diagonal_crossing_between_samples_is_a_collision() -> None:
    # every sample outside; only the segment from (19, 3) to (23, -3) crosses the zone (through (21, 0))
    x, y = np.array([0.0, 19.0, 23.0, 40.0]), np.array([3.0, 3.0, -3.0, -3.0])
    t = np.array([0.0, 0.1, 0.2, 0.3])
    v = judge(t, x, y, np.zeros(4), np.ones(4), np.zeros(4), ZONE, FIELD, 0.3)
    assert v.collided and v.min_clearance_m == 0.0
    assert np.all(ZONE.clearance(x, y) > 0.0)


def test_flags_are_independent_of_the_outcome_that_wins() -> None:
    t = np.arange(0.0, END + 1e-9, 0.01)
    v = run(t, 6.0 * t, np.where(t > 6.0, 11.0, 0.0), theta=np.where(t > 7.0, 2.0, 0.0))
    assert v.outcome == "collision"  # the first that applies
    assert v.collided and v.lost_control and v.left_field and v.complete and v.passed_obstacle


def test_bad_shapes_are_refused_and_missing_values_are_gaps() -> None:
    with pytest.raises(ValueError, match="^t, x, y, theta, vx, vy must be 1-D arrays of equal length$"):
        judge(np.zeros(3), np.zeros(2), np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3), ZONE, FIELD, 1.0)
    with pytest.raises(ValueError, match="1-D arrays"):
        judge(np.zeros((2, 2)), np.zeros((2, 2)), np.zeros((2, 2)), np.zeros((2, 2)), np.zeros((2, 2)),
              np.zeros((2, 2)), ZONE, FIELD, 1.0)
    tr = straight(y=3.0)
    x = [float(v) for v in tr["x"]]
    x[300:400] = [None] * 100  # a reader's missing field: a gap, like NaN
    assert judge(tr["t"], x, tr["y"], tr["theta"], tr["vx"], tr["vy"], ZONE, FIELD, END).outcome == "incomplete"


def test_samples_out_of_order_are_judged_in_time_order_ties_in_the_order_given() -> None:
    tr = straight(y=3.0)
    order = np.arange(len(tr["t"]))[::-1]  # delivered backwards
    backwards = {k: a[order] for k, a in tr.items()}
    assert verdict(backwards) == verdict(tr)
    # 40 instants 0.2 s apart, two samples each (x, 3) and (x + 0.1, 3), delivered backwards (each instant's
    # pair in its own order).  At instant 16 the pair is A = (19, 3), B = (23, 3) and the next instant is at
    # (23, −3): in the order given the path runs A → B → (23, −3), beside and then behind the zone; with the
    # tie reversed it would run B → A → (23, −3), and A → (23, −3) crosses the zone.
    t = np.repeat(np.arange(40, dtype=float) * 0.2, 2)
    x = np.repeat(np.arange(40, dtype=float) * 1.2, 2) + np.tile([0.0, 0.1], 40)
    y = np.full_like(t, 3.0)
    x[32], x[33] = 19.0, 23.0
    x[34:] = 23.0 + np.arange(46) * 0.5
    y[34:] = -3.0
    args = (np.zeros_like(t), np.full_like(t, 6.0), np.zeros_like(t), ZONE, FIELD, float(t[-1]))
    forward = judge(t, x, y, *args)
    assert not forward.collided and forward.min_clearance_m == pytest.approx(math.sqrt(2.0))  # A, B to the corners
    pairs = np.arange(len(t))[::-1].reshape(-1, 2)[:, ::-1].ravel()
    assert judge(t[pairs], x[pairs], y[pairs], *args) == forward


def test_finite_or_none() -> None:
    from moose.verdict import finite_or_none

    assert finite_or_none(None) is None and finite_or_none(float("nan")) is None
    assert finite_or_none(float("inf")) is None and finite_or_none(-float("inf")) is None
    assert finite_or_none(np.float32(1.5)) == 1.5 and isinstance(finite_or_none(np.float32(1.5)), float)
    assert finite_or_none(0.0) == 0.0


quarter = st.integers(-16, 104).map(lambda v: v / 4)  # a 0.25 m grid: exact in binary, short segments too


@settings(max_examples=600, deadline=None)
@given(st.one_of(st.tuples(*[st.integers(-4, 26) for _ in range(4)]), st.tuples(quarter, quarter, quarter, quarter)))
@example((18, 0, 20, 0))  # ends on the near edge: a touch
@example((19, 3, 21, 1))  # through the corner (20, 2) only
@example((19.5, 0.0, 20.25, 0.0))  # shorter than a metre, into the zone
@example((21.0, -2.75, 21.0, -2.25))  # short, just outside
@example((20, 2, 22, 2))  # along an edge
def test_segment_box_test_equals_the_separating_axis_test(segment: tuple) -> None:
    """Coordinates on a 1 m and a 0.25 m grid against the zone [20, 22] × [−2, 2]: touching (an end on an edge,
    a segment along an edge, through a corner) is frequent, and so are segments shorter than a metre.  The
    reference: a segment and a closed box intersect iff their bounding boxes overlap and the box's corners are not
    all strictly on one side of the segment's line."""
    x0, y0, x1, y1 = segment
    box = ZONE
    overlap = (min(x0, x1) <= box.x_max and max(x0, x1) >= box.x_min
               and min(y0, y1) <= box.y_max and max(y0, y1) >= box.y_min)
    corners = [(cx, cy) for cx in (box.x_min, box.x_max) for cy in (box.y_min, box.y_max)]
    sides = [(x1 - x0) * (cy - y0) - (y1 - y0) * (cx - x0) for cx, cy in corners]
    separated = all(s > 0 for s in sides) or all(s < 0 for s in sides)
    assert segment_hits_box(x0, y0, x1, y1, box) == (overlap and not separated)


def test_exit_status_of_each_outcome_degraded_and_interrupted() -> None:
    """0 clear, 1 a failure, 3 incomplete; 4 only for a clear run that was degraded; 130 for Ctrl-C only."""
    from moose.verdict import EXIT_DEGRADED, EXIT_INTERRUPTED, exit_status

    outcomes = ("clear", "collision", "left_field", "lost_control", "stopped_short", "incomplete")
    assert [exit_status(o) for o in outcomes] == [0, 1, 1, 1, 1, 3]
    assert [exit_status(o, degraded=True) for o in outcomes] == [EXIT_DEGRADED, 1, 1, 1, 1, 3] and EXIT_DEGRADED == 4
    assert exit_status("collision", interrupted="SIGINT") == EXIT_INTERRUPTED == 130
    assert [exit_status(o, interrupted="SIGTERM") for o in outcomes] == [0, 1, 1, 1, 1, 3]


def test_segments_that_touch_the_closed_box_at_any_edge_are_candidates() -> None:
    """judge's prefilter (the segments whose bounding boxes meet the box) keeps a segment that only touches the closed
    box at an edge or a corner, from either side: such a touch is a hit (segment_hits_box)."""
    from moose.verdict import _near

    box = Obstacle(0.0, 1.0, 0.0, 1.0)
    touching = [((1.0, 2.0), (0.5, 0.5)),  # from the far x edge outwards
                ((-1.0, 0.0), (0.5, 0.5)),  # ending on the near x edge
                ((0.5, 0.5), (1.0, 2.0)),  # from the upper y edge upwards
                ((0.5, 0.5), (-1.0, 0.0)),  # ending on the lower y edge
                ((1.0, 2.0), (1.0, 2.0))]  # from the corner (1, 1) away
    for xs, ys in touching:
        assert _near(np.array(xs), np.array(ys), box) == [0], (xs, ys)
        assert segment_hits_box(xs[0], ys[0], xs[1], ys[1], box)
    assert _near(np.array([1.01, 2.0]), np.array([0.5, 0.5]), box) == []


def test_changed_limits_names_each_limit_that_differs() -> None:
    """The verdict's limits that differ from the defaults, each with its default, comma-separated; none: empty."""
    from moose.verdict import DEFAULT_PARAMS, changed_limits, limits_of

    default = limits_of(DEFAULT_PARAMS)
    assert changed_limits(default) == ""
    assert changed_limits({**default, "sideslip_max": 10.0, "max_gap": 0.5}) == (
        "sideslip_max = 10 instead of 0.35, max_gap = 0.5 instead of 0.2")


def test_a_segment_that_crosses_the_box_on_the_way_back_is_a_candidate() -> None:
    """The prefilter bounds each segment by its own two samples: a path that passes the box and comes back through
    it (in x, then in y) has that crossing segment as a candidate, wherever the path started."""
    from moose.verdict import _near

    box = Obstacle(0.0, 1.0, 0.0, 1.0)
    assert _near(np.array([-5.0, 5.0, 5.0, -5.0]), np.array([5.0, 5.0, 0.5, 0.5]), box) == [2]
    assert _near(np.array([5.0, 5.0, 0.5, 0.5]), np.array([-5.0, 5.0, 5.0, -5.0]), box) == [2]
