"""Closed-loop moose tests: the paper's experiments reproduced in lockstep simulation."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from moose.config import load_config
from moose.metrics import summarize
from moose.scenario import load_scenario
from moose.simulation import simulate
from moose.schema import Config

NINE = [
    "paper_v5_tau5", "paper_v5_tau4", "paper_v5_tau3",
    "paper_v6_w2.0", "paper_v6_w2.4", "paper_v6_w3.2",
    "paper_v7_tau2.8", "paper_v7_tau2", "paper_v7_tau1.4",
]


@pytest.fixture(scope="module")
def config() -> Config:
    return load_config()


def run(config: Config, name: str, planner: str, seed: int = 0, duration: float = 8.0) -> dict:
    scenario = dataclasses.replace(load_scenario(name), duration=duration)
    return summarize(simulate(config, scenario, planner=planner, seed=seed))


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("name", NINE)
def test_paper_case_is_collision_free_and_inside_the_field(
    config: Config, name: str, seed: int
) -> None:
    s = run(config, name, "combined", seed, duration=10.0)  # time to return after the tau = 5 s case
    assert not s["collided"], s
    assert not s["left_field"], s
    assert s["min_clearance_m"] > 0.0
    # the threat measures the detector reports match the paper's within the y_max calibration
    assert s["nu"] == pytest.approx(s["paper_nu"], abs=0.1 + 0.15 * s["paper_nu"])
    # the car returns towards its lane after passing (paper: "returning to the initial lateral position")
    assert abs(s["final_lateral_offset_m"]) < 0.5 * s["max_lateral_offset_m"]


def overreacted(mpc: dict, combined: dict, delta_max: float, ratio: float) -> bool:
    """The MPC alone saturated the steering and swung out ``ratio`` times as far as the combined planner."""
    return mpc["max_abs_steer_rad"] >= 0.95 * delta_max and (
        mpc["max_lateral_offset_m"] > ratio * combined["max_lateral_offset_m"])


def test_extreme_case_combined_succeeds_with_every_mpc_solve_capped(config: Config) -> None:
    """Paper, Sec. V-C: in the extreme case the MPC finds no solution within the computational limits and
    the MSF planner avoids the collision.  Every solve of the evasion (τ ≥ 0.5 s: the first second after
    detection, while the lateral motion is decided) stops at the cap; beside the obstacle the problem
    becomes easy and some solves converge."""
    scenario = dataclasses.replace(load_scenario("paper_v7_tau1.4"), duration=8.0)
    result = simulate(config, scenario, planner="combined", seed=0)
    combined = summarize(result)
    assert not combined["collided"] and not combined["left_field"], combined
    under_threat = [r for r in result.planning if r.threat is not None and r.mpc is not None]
    assert len(under_threat) >= 10
    evasion = [r for r in under_threat if r.threat.tau >= 0.5]
    assert len(evasion) >= 4 and {r.mpc.status for r in evasion} == {"capped"}
    assert max(r.blend.weight_mpc for r in under_threat) < 0.05  # the weight function hands over to the MSF


def test_extreme_case_mpc_alone_fails_or_overreacts(config: Config) -> None:
    """Paper, Sec. V-C: where the combined planner passes, the MPC alone at the paper's caps does not find
    a good manoeuvre: here it saturates the steering and swings out more than 1.3 times as far."""
    combined = run(config, "paper_v7_tau1.4", "combined")
    mpc = run(config, "paper_v7_tau1.4", "mpc")
    mpc_failed = mpc["collided"] or mpc["left_field"]
    assert mpc_failed or overreacted(mpc, combined, config.vehicle.delta_max, 1.3), (mpc, combined)


@pytest.mark.parametrize("name", ["compare_nu0.26", "compare_nu0.34"])
def test_comparison_case_mpc_alone_steers_at_the_limit_and_stays_out(
    config: Config, name: str
) -> None:
    """Paper, Sec. V-D: the MPC alone gives extreme steering commands; the combined planner avoids the
    obstacle inside the field limits and returns to its lane, the MPC alone stays out (the paper's
    barrier keeps rewarding distance)."""
    combined = run(config, name, "combined")
    mpc = run(config, name, "mpc")
    assert not combined["collided"] and not combined["left_field"], combined
    assert not mpc["collided"], mpc
    assert mpc["max_abs_steer_rad"] >= 0.95 * config.vehicle.delta_max, mpc
    assert abs(combined["final_lateral_offset_m"]) < 0.1 * combined["max_lateral_offset_m"], combined
    assert abs(mpc["final_lateral_offset_m"]) > 0.8 * mpc["max_lateral_offset_m"], mpc


@pytest.mark.xfail(strict=True, reason=(
    "contradicts the paper (docs/design.md, 'Where the simulation disagrees'): with the projected Newton "
    "solver at the paper's caps the MPC alone swings out no further than the combined planner in the "
    "comparison cases (4.9 vs 4.8 m, 6.1 vs 7.0 m)"))
@pytest.mark.parametrize("name", ["compare_nu0.26", "compare_nu0.34"])
def test_comparison_case_mpc_alone_overreacts_where_combined_is_smoother(
    config: Config, name: str
) -> None:
    """Paper, Sec. V-D: the MPC alone overreacts; it swings out further than the combined planner."""
    combined = run(config, name, "combined")
    mpc = run(config, name, "mpc")
    assert overreacted(mpc, combined, config.vehicle.delta_max, 1.05), (mpc, combined)


def test_same_seed_same_run_other_seed_other_noise(config: Config) -> None:
    scenario = load_scenario("paper_v6_w2.4")
    a = simulate(config, scenario, "combined", seed=3).trace
    b = simulate(config, scenario, "combined", seed=3).trace
    c = simulate(config, scenario, "combined", seed=4).trace
    for key in ("x", "y", "delta", "vx_hat"):
        np.testing.assert_array_equal(a[key], b[key])
    assert not np.array_equal(a["vx_hat"], c["vx_hat"])
