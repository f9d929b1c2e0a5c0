"""``moose reproduce``: the paper's claims judged by the runs on both roads, the readings the paper leaves open side by
side, and the pages docs/modelling.md, docs/results.md and README.md generated from them.

The runs come from the session's :class:`moose.reproduce.RunCache` (``paper_runs``, tests/conftest.py), which the
closed-loop tests share.  Besides the staleness of the documents, the verdicts and the key numbers are pinned here:
a criterion that changes silently fails a test.
"""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from moose.paper import PAPER_FRICTION
from moose.reproduce import (
    BASES,
    COMPARISON,
    EXTREME,
    MUS,
    NINE,
    RESULT_RUNS,
    VARIANTS,
    Claim,
    Run,
    RunCache,
    claims,
    render_claims,
    render_conditions,
    render_results,
    render_summary,
    render_variants,
    result_runs,
    update_document,
    variant_rows,
)

ROOT = Path(__file__).resolve().parents[1]
MODELLING = ROOT / "docs" / "modelling.md"
RESULTS = ROOT / "docs" / "results.md"
README = ROOT / "README.md"
STALE = "is stale: run `moose reproduce --write docs/modelling.md --write docs/results.md --write README.md`"


@pytest.fixture(scope="module")
def runs(paper_runs: RunCache) -> list[Run]:
    return result_runs(paper_runs)


@pytest.fixture(scope="module")
def found(paper_runs: RunCache) -> list[Claim]:
    return claims(paper_runs)


def test_other_planners_run_beside_the_papers_without_a_claim(paper_runs: RunCache) -> None:
    """``moose reproduce --planner aeb,combined``: the baseline is added (no MPC solver), combined is not run twice."""
    added = result_runs(paper_runs, scenarios=("paper_v7_tau1.4",), planners=["aeb", "combined"])
    solver = paper_runs.config.mpc.solver
    assert [r.label for r in added] == [f"combined ({solver})", "combined (paper_sqp)", "msf", "mpc (paper_sqp)",
                                        f"mpc ({solver})", "aeb"]
    assert added[-1].solver == "" and added[-1].summary["outcome"] == "collision"


def block(name: str, path: Path = RESULTS) -> str:
    text = path.read_text(encoding="utf-8")
    match = re.search(rf"<!-- BEGIN {name} -->\n(.*?)<!-- END {name} -->", text, re.S)
    assert match, f"{path.name} has no generated block {name!r}"
    return match.group(1)


def column(table: str, index: int) -> list[str]:
    rows = [line for line in table.strip().splitlines()[2:] if line.startswith("|")]
    return [line.split(" | ")[index].strip(" |") for line in rows]


def test_every_scenario_runs_with_every_planner(runs: list[Run]) -> None:
    assert len(runs) == len(NINE + COMPARISON) * len(RESULT_RUNS)
    assert {r.label for r in runs} == {"combined (projected_newton)", "combined (paper_sqp)", "msf",
                                       "mpc (paper_sqp)", "mpc (projected_newton)"}
    for r in runs:
        assert r.summary["outcome"] in ("clear", "collision", "left_field", "lost_control", "stopped_short")
        assert r.summary["complete"] and r.mu == PAPER_FRICTION == r.summary["mu"] == r.summary["mu_planning"]


def test_a_run_is_made_once_and_named_as_asked(paper_runs: RunCache) -> None:
    """The comparison cases of Fig. 10 are the 6 m/s cases of Fig. 8 under another name: one run, two names."""
    before = len(paper_runs)
    a = paper_runs.run("paper_v6_w2.4", "msf", 0.8)
    made = len(paper_runs)
    b = paper_runs.run("compare_nu0.26", "msf", 0.8)
    assert len(paper_runs) == made <= before + 1
    assert a.summary["scenario"] == "paper_v6_w2.4" and b.summary["scenario"] == "compare_nu0.26"
    assert {k: v for k, v in a.summary.items() if k != "scenario"} == \
        {k: v for k, v in b.summary.items() if k != "scenario"}
    assert a.summary["mu"] == a.summary["mu_planning"] == 0.8  # road and planning alike


# -- the claims: every row quoted, with a basis and a verdict on each road -----------------------------------------

PINNED = [  # (where, start of the criterion, holds at μ = 0.33, holds at μ = 0.8)
    ("Figs. 7–9", "abs(ν − ν_paper) ≤ 0.07", True, False),
    ("Sec. VI-A", "combined clear, speed within ±15 %", True, True),
    ("Sec. VI-A", "the largest abs δ* after detection lies beyond", False, True),
    ("Observation 1", "combined runs (MPC paper_sqp), 5 and 6 m/s, same run", True, True),
    ("Observation 1", "combined runs (MPC projected_newton), 5 and 6 m/s, same run", True, True),
    ("Sec. VI-B", "combined runs (MPC paper_sqp), w = 2.0 and 2.4 m", False, True),
    ("Sec. VI-B", "combined runs (MPC projected_newton), w = 2.0 and 2.4 m", False, True),
    ("Sec. VI-B", "the combined's speed reference v_x* rises above the speed at detection", True, True),
    ("Sec. VI-A", "the 1 Hz GPS's 0.2 s lag delays", False, False),
    ("Sec. VI-A", "as above, late fixes fused on arrival", False, True),
    ("Observation 2", "the lag's mean delay of the return at 6 m/s", False, False),
    ("Observation 2", "as above, late fixes fused on arrival", False, False),
    ("Sec. VI-C, Observation 3", "in all three 7 m/s cases", True, True),
    ("Sec. VI-C", "the MPC alone (paper_sqp) is not clear", True, False),
    ("Sec. VI-C", "the MPC alone (projected_newton) is not clear", True, False),
    ("Sec. VI-C", "combined clear, its abs δ* under the threat reaching", True, True),
    ("Sec. IV", "combined's mean w_MPC under the threat < 0.1", True, True),
    ("Fig. 10", "our MPC alone (paper_sqp", True, True),
    ("Fig. 10", "our MPC alone (projected_newton", True, True),
]


def test_each_claim_has_its_pinned_verdict_on_each_road(found: list[Claim]) -> None:
    assert [c.where for c in found] == [p[0] for p in PINNED]
    for c, (where, criterion, calibrated, dry) in zip(found, PINNED):
        assert c.criterion.startswith(criterion), (c.criterion, criterion)
        assert [mu for mu, _ in c.verdicts] == list(MUS) == [PAPER_FRICTION, 0.8]
        assert (c.verdict(PAPER_FRICTION).holds, c.verdict(0.8).holds) == (calibrated, dry), \
            f"{where}: {c.criterion}: {c.verdicts}"


def test_each_claim_quotes_the_paper_and_names_its_basis(found: list[Claim]) -> None:
    for c in found:
        assert c.basis in BASES
        assert "“" in c.paper or c.paper.startswith("(the same") or c.where == "Figs. 7–9", c.paper
    basis = {(c.where, c.criterion[:30]): c.basis for c in found}
    assert found[0].basis == "calibration"  # μ was fitted to the printed ν
    assert [c.basis for c in found if "4.5m/s" in c.paper] == ["by construction"]  # v_des = 6 m/s from detection on
    assert [c.basis for c in found if c.where == "Sec. IV"] == ["by construction"]  # T(τ) N(ν) hand over by design
    assert sum(b == "measured" for b in basis.values()) == len(found) - 3
    # the target the project set itself is not a claim of the paper
    assert not any("≥ 0.3" in c.criterion or "share of the blend" in c.paper for c in found)


def test_observation_1_is_read_within_one_run(found: list[Claim], paper_runs: RunCache) -> None:
    """Figs. 7–9 plot δ_MPC and δ of the same run: the MPC's own command is at the limit for most of the threat, the
    applied command rarely; measured on the combined run, not against a separate run of the MPC alone."""
    for solver in ("projected_newton", "paper_sqp"):
        settings = (("mpc.solver", solver),) if solver == "paper_sqp" else ()
        m = [paper_runs.run(n, "combined", PAPER_FRICTION, settings).measures for n in NINE[:6]]
        assert min(x.mpc_near_limit or 0.0 for x in m) >= 0.4
        assert max(x.command_near_limit or 0.0 for x in m) <= 0.25
        assert sum(x.mpc_variation or 0.0 for x in m) > sum(x.command_variation or 0.0 for x in m)


def test_the_papers_trigger_fires_in_the_extreme_case(paper_runs: RunCache) -> None:
    """Sec. VI-C: the MPC "cannot find a feasible solution" — its plans cross y_safe — and alone it does not pass in
    control; the combined planner, handed the maneuver, passes."""
    for settings in ((), (("mpc.solver", "paper_sqp"),)):
        alone = paper_runs.run(EXTREME, "mpc", PAPER_FRICTION, settings)
        assert alone.summary["outcome"] == "lost_control"
        assert 0 < alone.measures.barrier_violations < alone.measures.mpc_threat_plans
        assert alone.summary["mpc_status_counts"]["barrier_violated"] >= alone.measures.barrier_violations
    combined = paper_runs.run(EXTREME, "combined", PAPER_FRICTION)
    assert combined.summary["outcome"] == "clear"  # by 0.02 m with the car's latency chain (0.13 m without)
    assert combined.summary["min_clearance_m"] == pytest.approx(0.02, abs=0.015)
    assert combined.summary["mean_weight_mpc"] < 0.01 and combined.measures.barrier_violations > 0


def test_observation_2_with_and_without_the_late_fix_replay(paper_runs: RunCache) -> None:
    """The EKF's exact replay of late fixes removes the lag's effect on the return (within the trace's 10 ms); fused
    as current, the stale fixes delay it on dry asphalt by a tenth of a second or two, at 5 m/s as much as at 6."""
    from moose.reproduce.claims import GPS_LAG_FREE, REPLAY_OFF

    def delay(name: str, mu: float, settings: tuple) -> float:
        lagged = paper_runs.run(name, "combined", mu, settings).measures.return_time
        free = paper_runs.run(name, "combined", mu, GPS_LAG_FREE + settings).measures.return_time
        assert lagged is not None and free is not None
        return lagged - free

    for name in NINE[1:6]:
        assert abs(delay(name, 0.8, ())) <= 0.015
        assert 0.05 <= delay(name, 0.8, REPLAY_OFF) <= 0.3


def test_the_documented_claims_are_the_generated_ones(found: list[Claim]) -> None:
    """docs/results.md carries what `moose reproduce --write` generates: the same claims, verdicts and numbers."""
    assert block("claims").strip() == render_claims(found), f"docs/results.md {STALE}"


def test_the_documented_results_are_the_generated_ones(runs: list[Run]) -> None:
    assert block("conditions").strip() == render_conditions(runs) == (
        "Seed 0; timing `car`: sensor 10 ms, planning 20 ms, command 10 ms, delay compensation off."), \
        f"docs/results.md {STALE}"
    documented = block("results")
    generated = render_results(runs)
    for index in (0, 1, 4):  # scenario, planner, outcome
        assert column(documented, index) == column(generated, index), \
            f"docs/results.md {STALE}"


def test_the_readmes_summary_is_the_generated_one(runs: list[Run], found: list[Claim]) -> None:
    assert block("summary", README).strip() == render_summary(runs, found), \
        f"README.md {STALE}"


# -- the readings the paper leaves open ---------------------------------------------------------------------------

def test_the_documented_variants_are_the_generated_ones(paper_runs: RunCache) -> None:
    """The variants table of docs/modelling.md, checked on two of its variants (the default, which the claims' runs
    already hold, and the S-curve MSF): all their cells, on both roads."""
    documented = block("variants", MODELLING).strip().splitlines()
    assert [line.split(" | ")[0].strip("| ") for line in documented[2:]] == \
        [v.label for v in VARIANTS for _ in MUS], f"docs/modelling.md {STALE}"
    checked = [v for v in VARIANTS if v.label in ("default", "S-curve MSF")]
    generated = render_variants(variant_rows(paper_runs, checked)).splitlines()
    for line in generated[2:]:
        assert line in documented, f"docs/modelling.md {STALE}: {line}"


def test_the_default_readings_keep_every_paper_case_clear_on_both_roads(paper_runs: RunCache) -> None:
    """Whatever the readings chosen, the combined planner passes all nine cases in control on both roads."""
    from moose.config import load_config

    config = load_config()
    assert (config.msf.profile, config.weight.rho_reading, config.weight.nu_reading,
            config.weight.barrier_violated_factor, config.mpc.barrier) == ("nu_scaled", "fbl", "current", 0.0, "paper")
    for row in variant_rows(paper_runs, VARIANTS[:1]):
        assert [r.summary["outcome"] for r in row.runs] == ["clear"] * 9, row.mu


# -- the command -----------------------------------------------------------------------------------------------------

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


def test_the_command_writes_its_blocks_and_every_run(tmp_path: Path, paper_runs: RunCache, runs: list[Run],
                                                     found: list[Claim], monkeypatch: pytest.MonkeyPatch,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """``moose reproduce --write README.md --write docs/results.md --json F`` on copies whose generated blocks are
    stale: each block is replaced by what the command generates, the rest of each page is left as it was, and the
    JSON holds every run made.  The runs are the session's (the command asks for the default configuration and seed
    0, as ``paper_runs`` was made with)."""
    import json

    import moose.reproduce
    from moose.cli import main

    asked: list[tuple[object, int]] = []

    def session_runs(config: object, seed: int = 0, progress: object = None) -> RunCache:
        asked.append((config, seed))
        return paper_runs

    monkeypatch.setattr(moose.reproduce, "RunCache", session_runs)
    pages = {README: tmp_path / "README.md", RESULTS: tmp_path / "results.md"}
    for page, copy in pages.items():
        copy.write_text(re.sub(r"(<!-- BEGIN (\w+) -->\n).*?(<!-- END \2 -->)", r"\1stale\n\3",
                               page.read_text(encoding="utf-8"), flags=re.S), encoding="utf-8")
    out = tmp_path / "runs.json"
    assert main(["reproduce", "--write", str(pages[README]), "--write", str(pages[RESULTS]), "--json", str(out)]) == 0
    assert asked == [(paper_runs.config, 0)]
    printed = capsys.readouterr().out
    assert printed.startswith(render_claims(found))
    assert f"wrote summary of {pages[README]}" in printed
    assert f"wrote conditions, results, claims of {pages[RESULTS]}" in printed
    assert block("summary", pages[README]).strip() == render_summary(runs, found)
    assert block("claims", pages[RESULTS]).strip() == render_claims(found)
    assert block("results", pages[RESULTS]).strip() == render_results(runs)
    assert block("conditions", pages[RESULTS]).strip() == render_conditions(paper_runs.asked)
    for page, copy in pages.items():  # outside its blocks, each page is as it was
        outside = [re.sub(r"<!-- BEGIN (\w+) -->\n.*?<!-- END \1 -->", "", p.read_text(encoding="utf-8"), flags=re.S)
                   for p in (page, copy)]
        assert outside[0] == outside[1], page.name
    rows = json.loads(out.read_text(encoding="utf-8"))
    assert len(rows) == len(paper_runs.asked)
    by_run = {(r["scenario"], r["planner"], r["solver"], r["road_mu"], json.dumps(r["settings"], sort_keys=True)): r
              for r in rows}
    for run in runs:  # each result run's row: its summary
        row = by_run[(run.scenario, run.planner, run.solver, run.mu, json.dumps(dict(run.settings), sort_keys=True))]
        assert row["outcome"] == run.summary["outcome"] and row["min_clearance_m"] == run.summary["min_clearance_m"]
