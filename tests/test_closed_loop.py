"""Closed-loop moose tests: the paper's experiments in lockstep simulation, judged from the true state.

The paper's cases run at the friction calibrated to its ν (``mu: paper`` in their files,
:data:`moose.paper.PAPER_FRICTION`) and, as robustness checks, on grippier roads (μ = 0.5 and 0.8).
The paper's claims about the MPC alone are rows of ``moose reproduce`` (tests/test_reproduce.py).
"""
from __future__ import annotations

import dataclasses
from typing import Any, Optional

import numpy as np
import pytest

from moose.config import load_config
from moose.metrics import summarize
from moose.paper import PAPER_FRICTION
from moose.reproduce import DURATION, RunCache
from moose.scenario import adhoc_scenario, load_scenario
from moose.schema import Config
from moose.simulation import simulate

NINE = [
    "paper_v5_tau5", "paper_v5_tau4", "paper_v5_tau3",
    "paper_v6_w2.0", "paper_v6_w2.4", "paper_v6_w3.2",
    "paper_v7_tau2.8", "paper_v7_tau2", "paper_v7_tau1.4",
]


@pytest.fixture(scope="module")
def config() -> Config:
    return load_config()


def run(config: Config, name: str, planner: str = "combined", seed: int = 0, duration: float = 10.0,
        mu: Optional[float] = None, cache: Optional[RunCache] = None) -> dict[str, Any]:
    """The run's summary; from the session's ``cache`` (:class:`moose.reproduce.RunCache`, the default configuration
    at seed 0) when it holds such runs."""
    if cache is not None and seed == cache.seed and duration == DURATION and config == cache.config:
        return cache.run(name, planner, mu if mu is not None else PAPER_FRICTION).summary
    scenario = dataclasses.replace(load_scenario(name), duration=duration)
    if mu is not None:
        scenario = dataclasses.replace(scenario, mu=mu)
    return summarize(simulate(config, scenario, planner=planner, seed=seed))


def assert_safe(s: dict[str, Any]) -> None:
    """Passed the obstacle without touching it, in control, inside the field."""
    assert s["outcome"] == "clear", s["reason"]
    assert not s["collided"] and not s["lost_control"] and not s["left_field"] and s["complete"]
    assert s["min_clearance_m"] > 0.0
    assert s["max_abs_sideslip_rad"] < 0.35


EXTREME_AT_THE_EDGE = pytest.mark.xfail(strict=True, raises=AssertionError, reason=(
    "paper claim (Dodging the Moose, Sec. VI-C): at tau = 1.4 s, nu = 0.95 the combined planner avoids the "
    "obstacle.  With the car's latency chain (the default timing, 40 ms from sample to actuator) the margin is "
    "gone: seed 0 passes with 0.02 m, seed 1 collides (-0.02 m); seeds 0-9 collide in 7 of 10 (-0.04 to +0.03 m), "
    "while all ten pass with --timing ideal (docs/architecture.md, 'Latency budget')"))


@pytest.mark.parametrize("name, seed", [
    pytest.param(name, seed, marks=[EXTREME_AT_THE_EDGE] if (name, seed) == ("paper_v7_tau1.4", 1) else [])
    for seed in (0, 1) for name in NINE])
def test_paper_case_at_the_calibrated_friction(config: Config, name: str, seed: int, paper_runs: RunCache) -> None:
    s = run(config, name, seed=seed, cache=paper_runs)
    assert s["mu"] == s["mu_planning"] == PAPER_FRICTION  # one friction: the road's is the stack's
    assert_safe(s)
    # the threat the detector measured is the paper's: tau exactly, nu within the calibration's spread
    assert s["tau_s"] == pytest.approx(s["tau_scenario_s"], abs=0.02)
    assert s["nu"] == pytest.approx(s["paper_nu"], abs=0.07)
    # back in the lane after passing (the paper: "returning to the initial lateral position")
    assert abs(s["final_lateral_offset_m"]) < 0.5


@pytest.mark.parametrize("mu", [0.5, 0.8])
@pytest.mark.parametrize("name", NINE)
def test_paper_case_on_a_grippier_road(config: Config, name: str, mu: float, paper_runs: RunCache) -> None:
    s = run(config, name, mu=mu, cache=paper_runs)
    assert s["mu"] == s["mu_planning"] == mu
    assert_safe(s)


def test_a_spinning_car_is_reported_as_lost_control(config: Config) -> None:
    # 10 m/s on a road of mu = 0.3 with an obstacle 1.5 s ahead: the full maneuver spins the car
    scenario = dataclasses.replace(adhoc_scenario(10.0, 1.5, 2.0), mu=0.3)
    s = summarize(simulate(config, scenario))
    assert s["outcome"] == "lost_control" and s["lost_control"], s["reason"]
    assert s["max_abs_sideslip_rad"] > 1.0 and "sideslip" in s["reason"]
    assert s["min_clearance_m"] > 0.0  # it did not hit the obstacle: control was lost all the same


def test_nu_is_smaller_on_a_grippier_road(config: Config) -> None:
    # the same geometry is an easier threat where the tyres give more: nu is the simulated car's
    nus = [run(config, "paper_v7_tau1.4", mu=mu, duration=3.0)["nu"] for mu in (PAPER_FRICTION, 0.5, 0.8)]
    assert nus[0] == pytest.approx(0.95, abs=0.05)
    assert nus[0] > nus[1] > nus[2]


@pytest.mark.parametrize("name", ["compare_nu0.26", "compare_nu0.34"])
def test_every_planner_meets_the_same_threat(config: Config, name: str) -> None:
    runs = {p: run(config, name, p, duration=3.0) for p in ("combined", "mpc", "msf")}
    for s in runs.values():
        assert s["tau_s"] == pytest.approx(runs["combined"]["tau_s"], abs=0.01)
        assert s["nu"] == pytest.approx(runs["combined"]["nu"], abs=0.01)
        assert s["v_detect_mps"] == pytest.approx(load_scenario(name).v_init, abs=0.05)


def test_extreme_case_the_msf_planner_dominates(config: Config) -> None:
    """Paper, Sec. V-C: τ = 1.4 s, ν = 0.95: the MSF planner's near-limit maneuver avoids the collision."""
    scenario = load_scenario("paper_v7_tau1.4")
    result = simulate(config, scenario, planner="combined", seed=0)
    s = summarize(result)
    assert_safe(s)
    under_threat = [r for r in result.planning if r.threat is not None]
    assert max(r.blend.weight_mpc for r in under_threat) < 0.05
    assert s["max_abs_steer_rad"] >= 0.9 * config.vehicle.delta_max  # close to the limits of steering


def test_same_seed_same_run_other_seed_other_noise(config: Config) -> None:
    scenario = load_scenario("paper_v6_w2.4")
    a = simulate(config, scenario, "combined", seed=3).trace
    b = simulate(config, scenario, "combined", seed=3).trace
    c = simulate(config, scenario, "combined", seed=4).trace
    for key in ("x", "y", "delta", "vx_hat"):
        np.testing.assert_array_equal(a[key], b[key])
    assert not np.array_equal(a["vx_hat"], c["vx_hat"])


def test_a_deliberate_friction_mismatch_is_the_stacks_belief_only(tmp_path: Any) -> None:
    """--mu-estimate: the stack plans with its μ (ν, bounds), the road keeps the scenario's; both reported."""
    import json

    from moose.cli import main

    out = tmp_path / "s.json"
    assert main(["simulate", "--scenario", "paper_v7_tau1.4", "--duration", "2", "--mu-estimate", "0.8", "--no-bag",
                 "--json", str(out)]) in (0, 1, 3)
    s = json.loads(out.read_text())
    assert s["mu"] == PAPER_FRICTION and s["mu_planning"] == 0.8
    assert s["nu"] == pytest.approx(0.45, abs=0.03)  # the ν the stack believes: the 0.8 road's (calibration table)
