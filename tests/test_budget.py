"""The latency budget (:mod:`moose.budget`, ``moose budget``): which latency a point adds where, how a budget is
read off a series (held to the uncompensated outcome), and the generated table, line and figure."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from moose.budget import Budget, Point, budgets, latencies, run_point
from moose.config import load_config
from moose.metrics import summarize
from moose.scenario import load_scenario
from moose.simulation import simulate
from moose.timing import profile

EXTREME = "paper_v7_tau1.4"


def series(case: str, path: str, compensate: bool, outcomes: str) -> list[Point]:
    """Points at 0, 10, 20 … ms with the outcomes c(lear) / x (collision) / l(ost control)."""
    names = {"c": "clear", "x": "collision", "l": "lost_control"}
    return [Point(case, path, k * 0.01, compensate, names[o], 0.1) for k, o in enumerate(outcomes)]


def test_a_budget_is_the_last_latency_before_the_first_change_of_the_uncompensated_outcome() -> None:
    points = (series("a", "command", False, "cccxcc") + series("a", "command", True, "ccccc")
              + series("a", "planning", False, "cccc") + series("a", "planning", True, "xccc"))
    found = {(b.path, b.compensate): b for b in budgets(points)}
    assert found[("command", False)] == Budget("a", "command", False, 0.02, False, "clear", "collision")
    assert found[("command", True)] == Budget("a", "command", True, 0.04, True, "clear", None)  # at least 40 ms
    assert found[("planning", False)].whole_range and found[("planning", False)].budget_s == pytest.approx(0.03)
    # compensation that changes the outcome with no added latency has no budget
    assert found[("planning", True)] == Budget("a", "planning", True, None, False, "clear", "collision")
    with pytest.raises(ValueError, match="must start at 0"):
        budgets(series("b", "command", False, "cc")[1:] + series("b", "command", True, "cc"))


def test_latencies_lie_on_the_resolution() -> None:
    assert latencies(0.05, 0.01) == [0.0, 0.01, 0.02, 0.03, 0.04, 0.05]


@pytest.mark.parametrize("path, delay", [("command", "command_delay_s"), ("planning", "planning_delay_s")])
def test_a_point_adds_its_latency_to_its_path_of_the_configured_timing(path: str, delay: str) -> None:
    config = dataclasses.replace(load_config(), timing=profile("car"))
    point = run_point(config, EXTREME, path, 0.03, True, 1.5)
    timing = dataclasses.replace(profile("car", compensate=True), **{delay: getattr(profile("car"), delay) + 0.03})
    expected = summarize(simulate(dataclasses.replace(config, timing=timing),
                                  dataclasses.replace(load_scenario(EXTREME), duration=1.5)))
    assert (point.outcome, point.clearance_m) == (expected["outcome"], expected["min_clearance_m"])
    assert (point.case, point.path, point.added_s, point.compensate) == (EXTREME, path, 0.03, True)


def test_the_command_writes_its_blocks_and_figure(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from moose.cli import main

    doc = tmp_path / "d.md"
    doc.write_text("<!-- BEGIN budget -->\nold\n<!-- END budget -->\n<!-- BEGIN budget-summary -->\n"
                   "<!-- END budget-summary -->\n", encoding="utf-8")
    figure = tmp_path / "b.png"
    assert main(["budget", "--timing", "car", "--case", EXTREME, "--max-ms", "10", "--workers", "1",
                 "--figure", str(figure), "--write", str(doc)]) == 0
    text = doc.read_text(encoding="utf-8")
    assert "Added to the `car` timing (sensor 10 ms, planning 20 ms, command 10 ms)" in text
    assert f"| {EXTREME} | clear |" in text and "Latency budget of the extreme case" in text
    assert figure.stat().st_size > 10_000


@pytest.mark.parametrize("argv, message", [
    (["--step-ms", "15"], "--step-ms = 15.0 is invalid: expected a whole number of motion-control periods"),
    (["--case", "no_such_case"], "no_such_case"),
    (["--max-ms", "5"], "--max-ms = 5.0 is invalid"),
    (["--case", "paper_v5_tau5", "--write", str(Path(__file__).resolve().parents[1] / "README.md")],
     "which --case leaves out"),
])
def test_bad_input_is_refused_before_anything_runs(argv: list[str], message: str,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    from moose.cli import main

    assert main(["budget", *argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith("moose: error:") and message in err
