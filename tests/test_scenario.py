"""Scenario files: the paper's experiments load, and bad files name the field and value."""
from __future__ import annotations

from pathlib import Path

import pytest

from moose.params import ParamError
from moose.scenario import adhoc_scenario, available_scenarios, load_scenario

PAPER = {
    "paper_v5_tau5": (5.0, 5.0, 4.0, 0.25),
    "paper_v5_tau4": (5.0, 4.0, 3.2, 0.26),
    "paper_v5_tau3": (5.0, 3.0, 2.4, 0.32),
    "paper_v6_w2.0": (6.0, 3.0, 2.0, 0.21),
    "paper_v6_w2.4": (6.0, 3.0, 2.4, 0.26),
    "paper_v6_w3.2": (4.5, 3.0, 3.2, 0.34),
    "paper_v7_tau2.8": (7.0, 2.8, 2.0, 0.19),
    "paper_v7_tau2": (7.0, 2.0, 2.0, 0.40),
    "paper_v7_tau1.4": (7.0, 1.4, 2.0, 0.95),
}


def test_the_nine_experiments_and_two_comparisons_ship() -> None:
    names = set(available_scenarios())
    assert set(PAPER) <= names
    assert {"compare_nu0.26", "compare_nu0.34"} <= names


@pytest.mark.parametrize("name", sorted(PAPER))
def test_paper_geometry(name: str) -> None:
    v, tau, w, nu = PAPER[name]
    s = load_scenario(name)
    assert s.v_init == v and s.tau == tau and s.paper.nu == nu
    assert s.obstacle.y_max == w and s.obstacle.y_min == -w
    # the obstacle appears when the near edge is v tau ahead of the CoG
    assert s.obstacle.x_min - s.x_appear == pytest.approx(v * tau)
    assert s.start_x < s.x_appear


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    return path


BASE = "name: t\nv_init: 5.0\nv_des: 5.0\ntau: 3.0\nobstacle: {x_min: 20, x_max: 22, y_min: -2, y_max: 2}\n"


@pytest.mark.parametrize(
    "text, needle",
    [
        (BASE.replace("v_init: 5.0", "v_init: -5.0"), "bad.v_init = -5.0"),
        (BASE.replace("tau: 3.0", "tau: fast"), "bad.tau = 'fast'"),
        (BASE.replace("y_min: -2", "y_min: 3"), "bad.obstacle.y_min = 3.0"),
        (BASE + "colour: red\n", "bad.colour = 'red' is unknown"),
        (BASE + "mu: 7\n", "bad.mu = 7.0"),
        (BASE + "field: {x_min: 10, x_max: 100, y_min: -5, y_max: 10}\n", "bad.field = {'x_min': 10.0"),
        ("- just a list\n", "expected a mapping"),
    ],
)
def test_invalid_files_name_field_and_value(tmp_path: Path, text: str, needle: str) -> None:
    with pytest.raises(ParamError) as info:
        load_scenario(write(tmp_path, text))
    assert needle in str(info.value)


def test_unknown_name_lists_shipped_scenarios() -> None:
    with pytest.raises(ParamError, match="paper_v7_tau1.4"):
        load_scenario("no_such_case")


def test_adhoc_centres_the_obstacle_on_the_path() -> None:
    s = adhoc_scenario(6.0, 2.5, 1.5, 3.0)
    assert (s.obstacle.y_min, s.obstacle.y_max) == (-1.5, 1.5)
    assert s.obstacle.x_max - s.obstacle.x_min == 3.0
    assert s.obstacle.x_min - s.x_appear == pytest.approx(15.0)
    with pytest.raises(ParamError, match="obstacle_half_width = -1"):
        adhoc_scenario(6.0, 2.5, -1.0)
