"""The run summary, checked against quantities computed here from the trace by other means; and a scenario that
must collide, reported as a collision with a negative clearance by the metric and by ``moose simulate``.

The collision scenario: 7 m/s, the obstacle 4 m to either side of the path, appearing 0.5 s ahead.  No car can
move 4 m sideways in 0.5 s: even at the friction limit μ g (μ = 0.8) the lateral displacement is
½ μ g t² = 0.98 m.  So every correct stack collides, whatever its planners do.
"""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from moose.config import load_config
from moose.metrics import smoothness, summarize
from moose.planner.step import PlanningRecord
from moose.scenario import adhoc_scenario
from moose.signals import Blend, Obstacle, PlanResult, Reference, Threat
from moose.simulation import SimulationResult, simulate

CONFIG = load_config()
SPEED, TAU, HALF_WIDTH, DURATION = 7.0, 0.5, 4.0, 2.0


def reference_clearance(box: Obstacle, x: float, y: float) -> float:
    """Signed distance to a box: outside, to its nearest point; inside, minus the distance to the nearest edge."""
    if box.x_min <= x <= box.x_max and box.y_min <= y <= box.y_max:
        return -min(x - box.x_min, box.x_max - x, y - box.y_min, box.y_max - y)
    return math.hypot(x - np.clip(x, box.x_min, box.x_max), y - np.clip(y, box.y_min, box.y_max))


def test_the_collision_scenario_cannot_be_avoided() -> None:
    p = CONFIG.vehicle
    assert 0.5 * p.mu * p.g * TAU**2 < HALF_WIDTH / 4  # a quarter of the way out at most


@pytest.fixture(scope="module")
def collision() -> SimulationResult:
    return simulate(CONFIG, adhoc_scenario(SPEED, TAU, HALF_WIDTH, duration=DURATION))


def test_a_scenario_that_must_collide_is_a_collision_in_the_summary(collision: SimulationResult) -> None:
    s = summarize(collision)
    tr, zone = collision.trace, collision.scenario.danger_zone
    assert s["outcome"] == "collision" and s["collided"] is True
    assert "danger zone" in s["reason"]
    gaps = [reference_clearance(zone, x, y) for x, y in zip(tr["x"], tr["y"])]
    assert min(gaps) < -0.5  # the CoG went deep into the zone
    assert s["min_clearance_m"] == pytest.approx(min(gaps), abs=1e-9)
    assert s["passed_obstacle"] is bool(np.any(tr["x"] > zone.x_max))


@pytest.mark.slow
def test_moose_simulate_reports_the_collision(tmp_path: Path) -> None:
    out, figure = tmp_path / "summary.json", tmp_path / "figure.png"
    proc = subprocess.run([sys.executable, "-m", "moose.cli", "simulate", "--speed", str(SPEED), "--tau", str(TAU),
                           "--obstacle-half-width", str(HALF_WIDTH), "--duration", str(DURATION), "--json", str(out),
                           "--plot", str(figure), "--no-bag"], capture_output=True, text=True, timeout=300)
    from moose.verdict import EXIT_FAILED

    assert proc.returncode == EXIT_FAILED == 1, proc.stderr  # the exit status of a collision, never a traceback
    assert "Traceback" not in proc.stderr
    assert "COLLISION" in proc.stdout
    summary = json.loads(out.read_text())
    assert summary["outcome"] == "collision" and summary["collided"] is True and summary["min_clearance_m"] < -0.5
    # the figure (make run's): a PNG of the three panels with the danger zone drawn in red
    import matplotlib.image

    image = matplotlib.image.imread(figure)
    assert image.shape[0] > image.shape[1] > 500  # three panels above each other
    zone_red = np.array([0.8 * 214 + 0.2 * 255, 0.8 * 39 + 0.2 * 255, 0.8 * 40 + 0.2 * 255]) / 255  # tab:red, α 0.8
    assert np.sum(np.all(np.abs(image[:, :, :3] - zone_red) < 0.02, axis=2)) > 200


# -- the summary's other quantities, on hand-made runs whose answers are known

SCENARIO = adhoc_scenario(6.0, 2.0, 1.0, duration=3.0)  # the zone from x = 12 to 14, y in [-1, 1]
END = SCENARIO.lead_time + SCENARIO.duration


def hand_made(y: float = 2.5, delta=None, planning=(), threat=None, vx: float = 6.0) -> SimulationResult:
    t = np.arange(0.0, END + 1e-9, 0.01)
    x = SCENARIO.start_x + vx * t
    trace = {"t": t, "x": x, "y": np.full_like(t, y), "theta": np.zeros_like(t), "vx": np.full_like(t, vx),
             "vy": np.zeros_like(t), "delta": np.zeros_like(t) if delta is None else delta(t)}
    return SimulationResult(SCENARIO, "combined", 3, trace, list(planning), threat, CONFIG, END)


def plan(t: float, status: str, solve_ms: float, weight: float, threat) -> PlanningRecord:
    accel = np.zeros((3, 2))
    mpc = PlanResult(accel, status, 5, solve_ms / 1e3, 1.0, np.zeros((4, 4)))
    return PlanningRecord(t, threat, mpc, None, Blend(weight, accel), Reference(0.0, 6.0), 0.0)


def test_a_clear_run_is_summarised_from_its_trace() -> None:
    s = summarize(hand_made(y=2.5))
    assert s["outcome"] == "clear" and not s["collided"] and s["complete"] and s["passed_obstacle"]
    assert s["min_clearance_m"] == pytest.approx(1.5)  # 2.5 − y_max 1.0
    assert s["scenario"] == SCENARIO.name and s["planner"] == "combined" and s["seed"] == 3
    assert s["mu"] == CONFIG.vehicle.mu and s["mu_planning"] == CONFIG.mu_planning
    assert s["tau_scenario_s"] == 2.0 and s["duration_s"] == pytest.approx(END)
    assert s["max_lateral_offset_m"] == 0.0 and s["final_lateral_offset_m"] == 0.0
    assert s["min_speed_mps"] == s["max_speed_mps"] == 6.0
    assert s["max_abs_steer_rad"] == 0.0
    # no threat: no τ, ν, w; notes say why; JSON-safe
    assert s["tau_s"] is None and s["nu"] is None and s["w_m"] is None and s["v_detect_mps"] is None
    assert s["notes"]["tau_s"] == s["notes"]["nu"] == "no obstacle was detected"
    assert s["notes"]["mean_weight_mpc"] == "no planning step had a threat"
    assert s["mpc_solve_ms"] == {"median": None, "p95": None, "max": None, "count": 0}
    assert s["steer_total_variation_rad"] is None and s["x_peak_steer_m"] is None
    json.dumps(s, allow_nan=False)


def test_threat_steering_and_planning_statistics() -> None:
    zone = SCENARIO.danger_zone
    threat = Threat(t=1.0, obstacle=zone, tau=1.9, w=1.2, nu=0.4, side=1, y_path=0.0)
    delta_max = CONFIG.vehicle.delta_max

    def steering(t: np.ndarray) -> np.ndarray:  # one sine period from t = 1.5 s, amplitude at the limit
        return np.where((t >= 1.5) & (t <= 2.5), delta_max * np.sin(2 * np.pi * (t - 1.5)), 0.0)

    planning = [plan(0.8, "converged", 10.0, float("nan"), None), plan(1.0, "converged", 20.0, 0.2, threat),
                plan(1.2, "capped", 40.0, 0.4, threat), plan(1.4, "failed", 30.0, 0.0, threat)]
    result = hand_made(y=2.5, delta=steering, planning=planning, threat=threat)
    s = summarize(result)
    assert (s["tau_s"], s["nu"], s["w_m"], s["paper_nu"]) == (1.9, 0.4, 1.2, SCENARIO.paper.nu)
    assert s["v_detect_mps"] == 6.0
    assert s["mpc_solve_ms"]["count"] == 4 and s["mpc_solve_ms"]["max"] == pytest.approx(40.0)
    assert s["mpc_solve_ms"]["median"] == pytest.approx(25.0)
    assert s["mpc_solve_ms"]["p95"] == pytest.approx(np.percentile([10.0, 20.0, 40.0, 30.0], 95))
    assert s["mpc_status_counts"] == {"capped": 1, "converged": 2, "failed": 1}
    assert s["mean_weight_mpc"] == pytest.approx((0.2 + 0.4 + 0.0) / 3)  # steps with a threat only
    # steering: a sine period of amplitude δ_max: total variation 4 δ_max, peak rate 2π δ_max, peak at t = 1.75 s
    assert s["max_abs_steer_rad"] == pytest.approx(delta_max, abs=1e-6)
    assert s["steer_total_variation_rad"] == pytest.approx(4 * delta_max, rel=1e-3)
    assert s["peak_steer_rate_rad_s"] == pytest.approx(2 * np.pi * delta_max, rel=1e-3)
    x_peak = SCENARIO.start_x + 6.0 * 1.75
    assert s["x_peak_steer_m"] == pytest.approx(x_peak - zone.x_max, abs=0.07)
    # within 1 mrad of the limit: |sin| ≥ 1 − 1e-3/δ_max around both extrema
    at_limit = 2 * (2 * np.arccos(1 - 1e-3 / delta_max) / (2 * np.pi))
    assert s["time_at_steer_limit_s"] == pytest.approx(at_limit, abs=0.021)
    assert "tau_s" not in s["notes"] and "mean_weight_mpc" not in s["notes"]


def test_an_infinite_nu_or_tau_is_null_with_the_reason() -> None:
    zone = SCENARIO.danger_zone
    past = Threat(t=1.0, obstacle=zone, tau=-0.5, w=1.2, nu=math.inf, side=1, y_path=0.0)
    s = summarize(hand_made(threat=past))
    assert s["nu"] is None and "no lateral displacement is possible" in s["notes"]["nu"]
    receding = Threat(t=1.0, obstacle=zone, tau=math.inf, w=1.2, nu=0.0, side=1, y_path=0.0)
    s = summarize(hand_made(threat=receding))
    assert s["tau_s"] is None and "not closing in" in s["notes"]["tau_s"]
    odd = Threat(t=1.0, obstacle=zone, tau=1.0, w=1.2, nu=-math.inf, side=1, y_path=0.0)
    assert summarize(hand_made(threat=odd))["notes"]["nu"] == "not a number"


def test_a_trace_without_finite_samples_is_incomplete_with_nulls() -> None:
    result = hand_made()
    for key in ("x", "y", "vx", "delta"):
        result.trace[key] = np.full_like(result.trace["t"], np.nan)
    s = summarize(result)
    assert s["outcome"] == "incomplete" and s["complete"] is False and s["min_clearance_m"] is None
    assert s["max_lateral_offset_m"] is None and s["final_lateral_offset_m"] is None
    assert s["min_speed_mps"] is None and s["max_speed_mps"] is None and s["max_abs_steer_rad"] is None
    json.dumps(s, allow_nan=False)


def test_smoothness_of_a_known_steering_signal() -> None:
    t = np.linspace(0.0, 2.0, 201)
    delta = np.where(t < 1.0, 0.1 * t, 0.1)  # a ramp at 0.1 rad/s to 0.1 rad, then held at the limit 0.1
    s = smoothness(t, delta, delta_max=0.1, t_from=0.5)
    assert s["steer_total_variation_rad"] == pytest.approx(0.05)
    assert s["peak_steer_rate_rad_s"] == pytest.approx(0.1)
    assert s["time_at_steer_limit_s"] == pytest.approx(1.0 + 0.01, abs=1e-9)  # from 0.99 s (within 1 mrad) to the end
    nothing = smoothness(t, delta, 0.1, t_from=1.995)
    assert nothing == {"steer_total_variation_rad": None, "time_at_steer_limit_s": None, "peak_steer_rate_rad_s": None}
    gappy = np.where(t > 1.5, np.nan, delta)
    assert smoothness(t, gappy, 0.1, 0.0)["time_at_steer_limit_s"] == pytest.approx(0.51, abs=1e-9)


SUMMARY_KEYS = {
    "scenario", "planner", "seed", "outcome", "reason", "collided", "lost_control", "left_field", "complete",
    "passed_obstacle", "min_clearance_m", "max_abs_sideslip_rad", "max_abs_heading_rad", "verdict_limits",
    "verdict_limits_default", "mu", "mu_planning", "timing",
    "tau_scenario_s", "tau_s", "nu", "w_m", "v_detect_mps", "paper_nu", "max_abs_steer_rad", "x_peak_steer_m",
    "max_lateral_offset_m", "final_lateral_offset_m", "min_speed_mps", "max_speed_mps", "mpc_solve_ms",
    "mpc_status_counts", "mean_weight_mpc", "duration_s", "steer_total_variation_rad", "time_at_steer_limit_s",
    "peak_steer_rate_rad_s", "commonroad_verdict", "criticality", "notes",
}
"""The summary's fields: what `moose simulate --json`, `moose launch --json`, the sweep's table and bag tools read."""


def test_the_summary_has_exactly_its_documented_fields() -> None:
    assert set(summarize(hand_made())) == SUMMARY_KEYS
    zone = SCENARIO.danger_zone
    threat = Threat(t=1.0, obstacle=zone, tau=1.9, w=1.2, nu=0.4, side=1, y_path=0.0)
    assert set(summarize(hand_made(threat=threat))) == SUMMARY_KEYS
    assert set(summarize(hand_made())["mpc_solve_ms"]) == {"median", "p95", "max", "count"}
    assert set(summarize(hand_made())["timing"]) == {"profile", "sensor_delay_s", "planning_delay_s",
                                                     "command_delay_s", "compensate"}


def test_a_detected_threat_fills_tau_nu_w_and_the_speed_at_detection() -> None:
    zone = SCENARIO.danger_zone
    threat = Threat(t=1.005, obstacle=zone, tau=1.9, w=1.2, nu=0.4, side=1, y_path=0.0)
    result = hand_made(threat=threat)
    result.trace["vx"] = 6.0 + result.trace["t"]  # the speed at detection: the first sample at or after t = 1.005
    s = summarize(result)
    assert (s["tau_s"], s["nu"], s["w_m"]) == (1.9, 0.4, 1.2)
    assert s["v_detect_mps"] == pytest.approx(6.0 + 1.01)
    assert s["min_speed_mps"] == pytest.approx(6.0) and s["max_speed_mps"] == pytest.approx(6.0 + END)
    assert "nu" not in s["notes"] and "tau_s" not in s["notes"]


def test_lateral_offsets_are_from_the_first_finite_sample() -> None:
    result = hand_made(y=2.5)
    y = result.trace["y"]
    y[:3] = np.nan  # the first samples missing: offsets from the first finite one
    y[3:] = 2.5 + np.sin(result.trace["t"][3:])
    s = summarize(result)
    offsets = y[3:] - y[3]
    assert s["max_lateral_offset_m"] == pytest.approx(np.max(np.abs(offsets)))
    assert s["final_lateral_offset_m"] == pytest.approx(offsets[-1])
    assert s["final_lateral_offset_m"] < 0.0  # sin(4) < sin(0.03): signed, not absolute


def test_every_non_finite_number_becomes_null_with_a_note() -> None:
    from moose.metrics import _json_safe

    notes: dict[str, str] = {}
    value = {"a": float("nan"), "b": [1.0, np.float64("inf"), {"c": -np.inf}], "d": (np.int64(3), np.bool_(True)),
             "e": "text", "f": np.float32(2.5)}
    safe = _json_safe(value, notes)
    assert safe == {"a": None, "b": [1.0, None, {"c": None}], "d": [3, True], "e": "text", "f": 2.5}
    assert type(safe["d"][0]) is int and type(safe["d"][1]) is bool and type(safe["f"]) is float
    assert notes == {"a": "not a finite number (nan)", "b": "not a finite number (inf)",
                     "c": "not a finite number (-inf)"}
    explained = {"a": "why"}
    _json_safe({"a": float("nan")}, explained)
    assert explained == {"a": "why"}  # a note that explains it already is kept
    json.dumps(safe, allow_nan=False)


def test_smoothness_boundaries() -> None:
    t = np.array([0.0, 0.01])
    two = smoothness(t, np.array([0.0, 0.01]), delta_max=0.3, t_from=0.0)  # two samples are enough
    assert two["steer_total_variation_rad"] == pytest.approx(0.01)
    assert two["peak_steer_rate_rad_s"] == pytest.approx(1.0)
    # within 1 mrad of the limit counts, exactly 1 mrad too; the sample at t_from counts
    t = np.arange(0.0, 0.05, 0.01)
    delta = np.array([0.299, 0.2989, 0.3, 0.3, 0.3])
    s = smoothness(t, delta, delta_max=0.3, t_from=0.0)
    assert s["time_at_steer_limit_s"] == pytest.approx(0.03)  # 0.299 (exactly 1 mrad), 0.3, 0.3; not 0.2989
    assert smoothness(t, delta, 0.3, t_from=0.01)["steer_total_variation_rad"] == pytest.approx(0.0011)


def test_a_run_without_any_sample_is_incomplete_with_every_quantity_null_and_explained() -> None:
    """The launcher's case when no odometry arrived: nothing is made up."""
    result = hand_made()
    result.trace = {k: a[:0] for k, a in result.trace.items()}
    s = summarize(result)
    assert s["outcome"] == "incomplete" and s["reason"] == "no samples of the vehicle state"
    for key in ("min_clearance_m", "max_abs_steer_rad", "max_lateral_offset_m", "final_lateral_offset_m",
                "min_speed_mps", "max_speed_mps", "duration_s", "steer_total_variation_rad"):
        assert s[key] is None, key
    # a None that is no failure has no note of its own; the CommonRoad verdict has nothing to judge, the criticality
    # measures were not asked for
    assert set(s["notes"]) == {"tau_s", "nu", "mean_weight_mpc", "commonroad_verdict", "criticality"}
    json.dumps(s, allow_nan=False)


def test_missing_values_are_null_without_a_spurious_note() -> None:
    result = hand_made()
    for key in ("vx", "delta"):
        result.trace[key] = np.full_like(result.trace["t"], np.nan)
    s = summarize(result)
    assert s["min_speed_mps"] is s["max_speed_mps"] is s["max_abs_steer_rad"] is None
    assert not {"min_speed_mps", "max_speed_mps", "max_abs_steer_rad", "median"} & set(s["notes"])


def test_the_speed_at_detection_is_the_sample_at_the_detection_time() -> None:
    zone = SCENARIO.danger_zone
    result = hand_made(threat=Threat(t=1.0, obstacle=zone, tau=1.9, w=1.2, nu=0.4, side=1, y_path=0.0))
    result.trace["vx"] = 6.0 + result.trace["t"]
    assert result.trace["t"][100] == 1.0
    assert summarize(result)["v_detect_mps"] == 7.0  # the sample at exactly t = 1.0 s, not the next one


def test_the_configured_verdict_thresholds_are_used() -> None:
    import dataclasses

    from moose.schema import VerdictParams

    result = hand_made()
    result.trace["vy"] = np.full_like(result.trace["t"], 0.3)  # β = 0.05 rad
    assert summarize(result)["outcome"] == "clear"
    result.config = dataclasses.replace(CONFIG, verdict=VerdictParams(sideslip_max=0.04))
    assert summarize(result)["outcome"] == "lost_control"


def test_notes_say_why_tau_nu_and_the_weight_are_null() -> None:
    zone = SCENARIO.danger_zone
    past = summarize(hand_made(threat=Threat(t=1.0, obstacle=zone, tau=-0.5, w=1.2, nu=math.inf, side=1, y_path=0.0)))
    assert past["notes"]["nu"] == "no lateral displacement is possible before the obstacle (τ ≤ 0 or v_x ≤ 0)"
    receding_threat = Threat(t=1.0, obstacle=zone, tau=math.inf, w=1.2, nu=0.0, side=1, y_path=0.0)
    receding = summarize(hand_made(threat=receding_threat))
    assert receding["notes"]["tau_s"] == "the car was not closing in on the obstacle (v_x ≤ 0)"
    threat = Threat(t=1.0, obstacle=zone, tau=1.9, w=1.2, nu=0.4, side=1, y_path=0.0)
    unweighted = summarize(hand_made(threat=threat, planning=[plan(1.0, "converged", 10.0, float("nan"), threat),
                                                              plan(1.2, "converged", 10.0, 0.9, None)]))
    assert unweighted["mean_weight_mpc"] is None  # the step without a threat does not count
    assert unweighted["notes"]["mean_weight_mpc"] == "no planning step with a threat recorded a weight"


def test_idle_planning_steps_are_no_threat_and_nothing_warns() -> None:
    import warnings

    idle = [plan(0.2 * k, "converged", 10.0, 0.0, None) for k in range(5)]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no mean of an empty list, no NaN arithmetic behind a null
        s = summarize(hand_made(planning=idle))
    assert s["mean_weight_mpc"] is None and s["notes"]["mean_weight_mpc"] == "no planning step had a threat"
    assert s["mpc_solve_ms"]["count"] == 5


def test_summarize_passes_the_criticality_request_on(monkeypatch: pytest.MonkeyPatch) -> None:
    """``summarize(result, criticality=True)`` asks :func:`moose.commonroad.assess.assess` for the measures: told
    here that the CommonRoad packages are missing, its note says so, where a summary not asking for them says they
    were not asked for (commonroad-crime itself takes seconds to import: tests/test_commonroad.py runs it)."""
    import moose.commonroad.assess as assess_module

    monkeypatch.setattr(assess_module, "available", lambda: False)
    asked, not_asked = summarize(hand_made(), criticality=True), summarize(hand_made())
    assert asked["criticality"] is None and not_asked["criticality"] is None
    assert "not installed" in asked["notes"]["criticality"], asked["notes"]
    assert not_asked["notes"]["criticality"] == "not computed: ask with --criticality"
