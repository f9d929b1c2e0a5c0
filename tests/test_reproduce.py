"""``moose reproduce``: the paper's claims judged by the runs, and docs/design.md generated from them."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from moose.config import load_config
from moose.reproduce import (
    COMPARISON,
    NINE,
    RUNS,
    Claim,
    Run,
    claims,
    render_claims,
    render_results,
    render_summary,
    run_all,
    update_document,
)

ROOT = Path(__file__).resolve().parents[1]
DESIGN = ROOT / "docs" / "design.md"
README = ROOT / "README.md"


@pytest.fixture(scope="module")
def runs() -> list[Run]:
    return run_all(load_config())


@pytest.fixture(scope="module")
def found(runs: list[Run]) -> list[Claim]:
    config = load_config()
    return claims(runs, config.mpc.solver, config.vehicle.delta_max)


def test_every_scenario_runs_with_every_planner(runs: list[Run]) -> None:
    assert len(runs) == len(NINE + COMPARISON) * len(RUNS)
    assert {r.label for r in runs} >= {"combined", "msf"}
    for r in runs:
        assert r.summary["outcome"] in ("clear", "collision", "left_field", "lost_control", "stopped_short")
        assert r.summary["complete"]


def test_other_planners_run_beside_the_papers_without_a_claim() -> None:
    """``moose reproduce --planner aeb,combined``: the baseline is added (no MPC solver), combined is not run twice."""
    added = run_all(load_config(), scenarios=("paper_v7_tau1.4",), planners=["aeb", "combined"])
    assert [r.label for r in added] == ["combined", "msf", "mpc (paper_sqp)", f"mpc ({load_config().mpc.solver})",
                                        "aeb"]
    assert added[-1].solver == "" and added[-1].summary["outcome"] == "collision"


def block(name: str, path: Path = DESIGN) -> str:
    text = path.read_text(encoding="utf-8")
    match = re.search(rf"<!-- BEGIN {name} -->\n(.*?)<!-- END {name} -->", text, re.S)
    assert match, f"{path.name} has no generated block {name!r}"
    return match.group(1)


def column(table: str, index: int) -> list[str]:
    rows = [line for line in table.strip().splitlines()[2:] if line.startswith("|")]
    return [line.split("|")[index + 1].strip() for line in rows]


def test_the_documented_claims_are_the_generated_ones(found: list[Claim]) -> None:
    """docs/design.md carries what `moose reproduce --write` generates: same claims, same verdicts."""
    documented = block("claims")
    generated = render_claims(found)
    assert column(documented, 1) == column(generated, 1)
    assert column(documented, 3) == column(generated, 3), "docs/design.md is stale: run `moose reproduce --write`"


def test_the_documented_results_are_the_generated_ones(runs: list[Run]) -> None:
    documented = block("results")
    generated = render_results(runs)
    assert column(documented, 0) == column(generated, 0) and column(documented, 1) == column(generated, 1)
    assert column(documented, 4) == column(generated, 4), "docs/design.md is stale: run `moose reproduce --write`"


def test_the_readmes_summary_is_the_generated_one(runs: list[Run], found: list[Claim]) -> None:
    assert block("summary", README).strip() == render_summary(runs, found), \
        "README.md is stale: run `moose reproduce --write docs/design.md --write README.md`"


def test_update_document_replaces_only_its_blocks(tmp_path: Path) -> None:
    path = tmp_path / "d.md"
    path.write_text("a\n<!-- BEGIN x -->\nold\n<!-- END x -->\nb\n", encoding="utf-8")
    update_document(path, {"x": "new\nlines"})
    assert path.read_text(encoding="utf-8") == "a\n<!-- BEGIN x -->\nnew\nlines\n<!-- END x -->\nb\n"
    with pytest.raises(ValueError, match="no '<!-- BEGIN y -->'"):
        update_document(path, {"y": "z"})


def test_the_command_refuses_bad_paths_before_running(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from moose.cli import main

    assert main(["reproduce", "--write", str(tmp_path / "missing.md")]) == 2
    assert "--write" in capsys.readouterr().err
    plain = tmp_path / "plain.md"
    plain.write_text("no generated blocks here\n", encoding="utf-8")
    assert main(["reproduce", "--write", str(plain)]) == 2
    assert "holds none of the generated blocks" in capsys.readouterr().err
    assert main(["reproduce", "--json", str(tmp_path / "no" / "such" / "out.json")]) == 2
    with pytest.raises(SystemExit) as exited:  # argparse's own error: "moose reproduce: error: argument --seed: …"
        main(["reproduce", "--seed", "-1"])
    assert exited.value.code == 2 and "--seed: '-1' must be a non-negative integer" in capsys.readouterr().err
