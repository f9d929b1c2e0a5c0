"""``moose benchmark``: the leaderboard's measures as defined (moose.benchmark), and the command end to end on a small
region (the real one is 4,500 cases: docs/benchmarks.md's leaderboard)."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

import moose.benchmark as benchmark
from moose.benchmark import HEADER, leaderboard, render_leaderboard
from moose.cli import main


def row(planner: str, speed: float, tau: float, nu: float, outcome: str, status: str = "done",
        clearance: float = 1.0, sideslip: float = 0.1, effort: float = 1.0) -> dict:
    return {"input.mu": 0.8, "input.planner": planner, "input.speed_mps": speed, "input.tau_s": tau, "input.nu": nu,
            "status": status, "outcome": outcome if status == "done" else None, "min_clearance_m": clearance,
            "max_abs_sideslip_rad": sideslip, "steer_total_variation_rad": effort}


def test_the_envelope_ends_at_the_first_failure_in_nu_and_the_shares_count_every_cell() -> None:
    """At (5 m/s, 2 s) the planner is clear at ν 0.1, 0.2, fails at 0.3 and is clear again at 0.4 (luck, not
    envelope); at (5 m/s, 3 s) it fails at once.  A stop short is collision-free, not clear; an unfinished case is
    neither."""
    rows = [row("p", 5, 2, 0.1, "clear", clearance=0.5), row("p", 5, 2, 0.2, "clear", clearance=1.5),
            row("p", 5, 2, 0.3, "collision", clearance=-0.2, sideslip=0.4),
            row("p", 5, 2, 0.4, "clear", clearance=1.0),
            row("p", 5, 3, 0.1, "stopped_short", clearance=9.0, effort=0.0), row("p", 5, 3, 0.2, "", "error")]
    (entry,) = leaderboard(rows)
    assert entry.cells == 6 and entry.unfinished == 1
    assert entry.envelope == pytest.approx(2 / 6) and entry.envelope_nu == {(5.0, 2.0): 0.2, (5.0, 3.0): 0.0}
    assert entry.clear == pytest.approx(3 / 6) and entry.no_collision == pytest.approx(4 / 6)
    assert entry.mean_clearance_m == pytest.approx(1.0)  # the clear cells only
    assert entry.worst_sideslip_rad == pytest.approx(0.4)
    assert entry.steering_effort_rad == pytest.approx((1 + 1 + 1 + 1 + 0) / 5)
    table = render_leaderboard([entry])
    assert "6 (1 unfinished)" in table and table.count("|") == 3 * (len(HEADER) + 1)


def test_planners_are_ranked_by_envelope_per_friction() -> None:
    rows = [row("weak", 5, 2, 0.1, "collision"), row("strong", 5, 2, 0.1, "clear")]
    assert [e.planner for e in leaderboard(rows)] == ["strong", "weak"]


def test_the_command_runs_every_planner_and_writes_the_leaderboard(tmp_path: Path, monkeypatch,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """On a region of two cells per friction and planner: the sweep, leaderboard.md and .png in the folder, the
    figure where asked, and the generated block of a document; a second run with --resume only draws again."""
    monkeypatch.setattr(benchmark, "AXES", {**benchmark.AXES, "speed": "7", "tau": "1.5,3", "nu": "0.5", "mu": "0.8"})
    doc = tmp_path / "benchmarks.md"
    doc.write_text("before\n<!-- BEGIN leaderboard -->\nold\n<!-- END leaderboard -->\nafter\n", encoding="utf-8")
    out, figure = tmp_path / "bench", tmp_path / "docs" / "leaderboard.png"
    args = ["benchmark", "-o", str(out), "--workers", "1", "--quiet", "--write", str(doc), "--figure", str(figure)]
    assert main(args) == 0
    table = (out / "leaderboard.md").read_text(encoding="utf-8")
    assert {line.split("|")[2].strip() for line in table.splitlines()[2:]} == {"combined", "mpc", "msf", "aeb",
                                                                                "max_steer"}
    assert re.search(r"\| 0\.8 \| aeb \| 0\.0 \| 0\.0 \|", table)  # it stops or collides: never passes
    assert (out / "leaderboard.png").stat().st_size > 0 and figure.stat().st_size > 0
    text = doc.read_text(encoding="utf-8")
    assert text.startswith("before\n<!-- BEGIN leaderboard -->\n" + table) and text.endswith("after\n")
    capsys.readouterr()
    assert main(args + ["--resume"]) == 0
    assert "ran             0 cases" in capsys.readouterr().out


def test_a_document_without_the_block_is_refused_before_any_case(tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    doc = tmp_path / "notes.md"
    doc.write_text("no block\n", encoding="utf-8")
    assert main(["benchmark", "-o", str(tmp_path / "bench"), "--write", str(doc)]) == 2
    assert "moose: error: --write" in capsys.readouterr().err and not (tmp_path / "bench").exists()
