"""``moose reproduce``: the paper's experiments and claims, re-run and judged by one command.

* :mod:`moose.reproduce.runs` — the paper's cases, the roads and the :class:`RunCache` that makes each run once;
* :mod:`moose.reproduce.claims` — every claim of the paper, quoted, held to a criterion on each road;
* :mod:`moose.reproduce.variants` — the readings the paper leaves open, measured side by side;
* :mod:`moose.reproduce.render` — the generated tables of docs/results.md and docs/modelling.md and the README's
  summary.

Every scenario runs with the combined planner (with the configured MPC solver and with the paper's fmincon
baseline ``paper_sqp``), the MSF planner alone and the MPC alone (both solvers), at the calibrated friction and
on dry asphalt (μ = 0.8), road and planning alike.
"""
from __future__ import annotations

from .claims import BASES, Basis, Claim, Verdict, claims, render_claims
from .render import (
    CALIBRATION_MU,
    RESULT_RUNS,
    blocks_in,
    render_calibration,
    render_conditions,
    render_results,
    render_summary,
    result_runs,
    update_document,
)
from .runs import (
    COMPARISON,
    DURATION,
    EXTREME,
    LOCK,
    MUS,
    NINE,
    PAPER_SOLVER,
    RETURN_BAND,
    Measures,
    Run,
    RunCache,
    measure,
)
from .variants import VARIANTS, Variant, VariantRow, render_variants, variant_rows

__all__ = [
    "BASES", "Basis", "CALIBRATION_MU", "COMPARISON", "Claim", "DURATION", "EXTREME", "LOCK", "MUS", "Measures",
    "NINE", "PAPER_SOLVER", "RESULT_RUNS", "RETURN_BAND", "Run", "RunCache", "VARIANTS", "Variant", "VariantRow",
    "Verdict", "blocks_in", "claims", "measure", "render_calibration", "render_claims", "render_conditions",
    "render_results", "render_summary", "render_variants", "result_runs", "update_document", "variant_rows",
]
