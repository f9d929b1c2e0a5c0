"""The baselines (moose.planner.baseline): emergency braking (``aeb``) and full lock (``max_steer``), each held to
its own definition in the closed loop, and their references made by the planning step alone (as in the graph)."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from moose.config import load_config
from moose.maneuver import MaxSteeringTable
from moose.metrics import summarize
from moose.planner import MODE_PLANNERS
from moose.planner.baseline import AebPlanner, MaxSteerPlanner
from moose.planner.msf import MsfPlanner
from moose.planner.step import PlanningStep
from moose.scenario import load_scenario
from moose.signals import Obstacle, PlannerInput, StateEstimate, Threat
from moose.simulation import SimulationResult, simulate

CONFIG = load_config()
THREAT = Threat(0.0, Obstacle(12.0, 14.0, -0.5, 2.0), 12.0 / 7.0, 2.0, 0.5, 1, 0.0)
RIGHT = dataclasses.replace(THREAT, side=-1)
CRUISE = StateEstimate(0.0, 0.0, 0.0, 0.0, 7.0, 0.0, 0.0, 0.0)
RUNS = {("paper_v5_tau5", "aeb"), ("paper_v7_tau1.4", "aeb"), ("paper_v7_tau1.4", "max_steer"),
        ("paper_v5_tau5", "max_steer")}


@pytest.fixture(scope="module")
def runs() -> dict[tuple[str, str], SimulationResult]:
    return {(name, planner): simulate(CONFIG, load_scenario(name), planner) for name, planner in sorted(RUNS)}


def after_detection(result: SimulationResult) -> np.ndarray:
    assert result.first_threat is not None
    return result.trace["t"] >= result.first_threat.t


def test_aeb_brakes_on_its_course_at_the_motors_full_braking(runs: dict) -> None:
    """From detection on: no steering aside, the deceleration of the braking limit a_x,max (measured between 90 %
    and 20 % of the speed: 1.376 of 1.395 m/s²), and the stop within v²/(2 a_x,max) plus 0.25 s of reaction at the
    approach speed (the torque's ramp to T_max and the detection); the car stops short of the zone."""
    result = runs["paper_v5_tau5", "aeb"]
    trace, v0 = result.trace, result.scenario.v_init
    a_max = result.config.model_vehicle.longitudinal_accel_limit
    after = after_detection(result)
    assert np.abs(trace["delta"][after]).max() < 0.01
    assert np.abs(trace["y"]).max() < 0.2
    t, vx = trace["t"], trace["vx"]
    fast, slow = int(np.argmax(after & (vx < 0.9 * v0))), int(np.argmax(after & (vx < 0.2 * v0)))
    assert (vx[fast] - vx[slow]) / (t[slow] - t[fast]) == pytest.approx(a_max, rel=0.03)
    x_detect = float(np.interp(result.first_threat.t, t, trace["x"]))
    assert trace["x"].max() - x_detect < v0 ** 2 / (2 * a_max) + 0.25 * v0
    assert summarize(result)["outcome"] == "stopped_short"


def test_aeb_cannot_stop_in_the_extreme_case(runs: dict) -> None:
    """7 m/s at τ = 1.4 s leaves 9.8 m; braking at 1.4 m/s² needs 17.5 m: the car runs into the zone, straight."""
    summary = summarize(runs["paper_v7_tau1.4", "aeb"])
    assert summary["outcome"] == "collision"
    assert summary["max_lateral_offset_m"] < 0.2


def test_max_steer_is_full_lock_while_the_threat_lasts_and_drives_y_max(runs: dict) -> None:
    """δ* = δ_max toward the evasion side at every tick of the threat from the detection's plan on (it acts the
    planning delay after the detection: the lane keeping's δ* until then), the steering at full lock t_lock after
    the detection (plus the EPS loop's lag), and the lateral displacement of eq. (ymax) from when the command reaches
    the wheels (d_p + d_c after the detection; within 6 % after 1 s; the car slows at full lock, which y_max at
    constant speed does not)."""
    result = runs["paper_v7_tau1.4", "max_steer"]
    trace, threat = result.trace, result.first_threat
    assert threat is not None and threat.side == 1
    delta_max = result.config.vehicle.delta_max
    under = trace["threat"] == 1.0
    acting = trace["t"] >= threat.t + result.config.timing.planning_delay_s - 1e-9
    assert np.all(trace["delta_ref"][under & acting] == delta_max)
    assert np.all(np.abs(trace["delta_ref"][under & ~acting]) < 0.1 * delta_max)
    table = MaxSteeringTable.build(result.config.model_vehicle, result.config.maneuver)
    t = trace["t"]
    assert float(np.interp(threat.t + table.t_lock + 0.15, t, trace["delta"])) > 0.97 * delta_max
    start = threat.t + result.config.timing.planning_delay_s + result.config.timing.command_delay_s  # wheels turn
    v = float(np.interp(start, t, trace["vx"]))
    moved = float(np.interp(start + 1.0, t, trace["y"]) - np.interp(start, t, trace["y"]))
    assert moved == pytest.approx(float(table.y_max(1.0, v)), rel=0.06)


def test_max_steer_is_the_panic_reaction_the_msf_planner_refines(runs: dict) -> None:
    """Without κ and the counter-steer, full lock until the threat clears turns the car across the road: in the
    extreme case it passes the obstacle and then loses control by its heading; at τ = 5 s it turns round before
    it reaches the obstacle."""
    extreme, relaxed = summarize(runs["paper_v7_tau1.4", "max_steer"]), summarize(runs["paper_v5_tau5", "max_steer"])
    assert extreme["outcome"] == relaxed["outcome"] == "lost_control"
    assert extreme["min_clearance_m"] > 0.0 and "heading" in extreme["reason"]
    assert relaxed["max_abs_heading_rad"] > math.pi


@pytest.mark.parametrize("mode", sorted(MODE_PLANNERS))
def test_each_mode_builds_the_planners_of_its_slots(mode: str) -> None:
    step = PlanningStep(CONFIG, mode)
    assert (step.mpc is not None) == ("mpc" in MODE_PLANNERS[mode])
    kind = {"aeb": AebPlanner, "max_steer": MaxSteerPlanner}.get(mode, MsfPlanner)
    assert type(step.msf) is kind if "msf" in MODE_PLANNERS[mode] else step.msf is None


@pytest.mark.parametrize("threat", [THREAT, RIGHT])
def test_the_combining_step_alone_commands_full_lock_for_max_steer(threat: Threat) -> None:
    """The ``weight_fbl`` node's step (no planners of its own) makes the baseline's reference from its plan: full
    lock toward the threat's side, held between planning instants; the FBL's δ* once the plan is the return."""
    planner = PlanningStep(CONFIG, "max_steer").msf
    assert planner is not None
    combining = PlanningStep(CONFIG, "max_steer", planners=False)
    plan = planner.plan(PlannerInput(0.0, CRUISE, threat, 7.0, None))
    record = combining.combine(0.0, CRUISE, threat, None, plan)
    assert record.reference.delta == threat.side * CONFIG.vehicle.delta_max
    later = dataclasses.replace(CRUISE, t=0.1, gamma=0.2 * threat.side)
    reference = combining.reference_at(0.1, later)
    assert reference is not None and reference.delta == threat.side * CONFIG.vehicle.delta_max
    idle = planner.plan(PlannerInput(0.2, dataclasses.replace(CRUISE, t=0.2), None, 7.0, None))
    assert idle.status == "idle"
    back = combining.combine(0.2, CRUISE, None, None, idle)
    assert abs(back.reference.delta) < 0.5 * CONFIG.vehicle.delta_max


def test_the_combining_step_alone_commands_standstill_for_aeb() -> None:
    """v_x* = 0 from the first braking plan on (the motion controller's full torque), also once the threat has
    cleared (the braking is latched); the lane keeping before the threat has the FBL's v_x*."""
    planner = PlanningStep(CONFIG, "aeb").msf
    assert planner is not None
    combining = PlanningStep(CONFIG, "aeb", planners=False)
    cruise = combining.combine(0.0, CRUISE, None, None, planner.plan(PlannerInput(0.0, CRUISE, None, 7.0, None)))
    assert cruise.reference.vx == pytest.approx(7.0, abs=0.05)
    braking = planner.plan(PlannerInput(0.2, CRUISE, THREAT, 7.0, None))
    a_max = CONFIG.grid.a_x_max
    np.testing.assert_allclose(braking.accel[:10], np.tile([-a_max, 0.0], (10, 1)))
    assert combining.combine(0.2, CRUISE, THREAT, None, braking).reference.vx == 0.0
    cleared = planner.plan(PlannerInput(0.4, CRUISE, None, 7.0, None))
    assert cleared.status == "ok" and combining.combine(0.4, CRUISE, None, None, cleared).reference.vx == 0.0


def test_the_aeb_plan_stops_at_rest_instead_of_reversing() -> None:
    """The predicted speed falls at a_x,max to zero and stays there (the last step ends at rest)."""
    crawl = dataclasses.replace(CRUISE, vx=0.5, theta=0.3)
    plan = AebPlanner(CONFIG.msf, CONFIG.grid, MaxSteeringTable.build(CONFIG.model_vehicle)).plan(
        PlannerInput(0.0, crawl, THREAT, 7.0, None))
    speed = np.hypot(plan.predicted[:, 2], plan.predicted[:, 3])
    assert np.all(np.diff(speed) <= 1e-12) and speed[-1] == pytest.approx(0.0, abs=1e-12)
    heading = np.arctan2(plan.accel[0, 1], plan.accel[0, 0])
    assert heading == pytest.approx(0.3 - math.pi)


@pytest.mark.graph
@pytest.mark.slow
@pytest.mark.parametrize("mode", ["aeb", "max_steer"])
def test_the_node_graph_runs_a_baseline_in_the_msf_planners_place(mode: str) -> None:
    """``moose launch --planner MODE``: the baseline in the ``msf_planner`` node, its reference made by
    ``weight_fbl``'s planning step; the outcome is the lockstep loop's (4 s after the obstacle appears).  The graph
    steps in lockstep (``--lockstep``): what it computes, whatever the machine's load."""
    import io

    from lockstep_reference import assert_reproduces
    from moose_ros.launch import launch

    scenario = dataclasses.replace(load_scenario("paper_v6_w2.4"), duration=4.0)
    summary = launch(scenario, {"scenario": scenario.name, "duration": scenario.duration}, planner=mode,
                     out=io.StringIO(), lockstep=True)
    lockstep = summarize(simulate(CONFIG, scenario, mode))
    assert summary["outcome"] == lockstep["outcome"] == {"aeb": "stopped_short", "max_steer": "lost_control"}[mode]
    assert summary["max_abs_steer_rad"] == pytest.approx(lockstep["max_abs_steer_rad"], abs=0.01)
    assert_reproduces(summary, lockstep)  # clearance to 1 mm, τ and ν to 1e-3
