"""The readings the paper leaves open, measured side by side (``moose reproduce --variants``).

A :class:`Variant` is a set of parameter settings that read the paper another way — the MSF's evasion profile
(``msf.profile``), how the weight function reads the MPC's steering (``weight.rho_reading``) and the threat
(``weight.nu_reading``), the factor of a plan through y_safe (``weight.barrier_violated_factor``) and the
barrier's shape (``mpc.barrier``).  Each runs the combined planner over the nine paper cases on every road of
:data:`~moose.reproduce.runs.MUS`; :func:`render_variants` writes one row per variant and road, which
docs/modelling.md carries ("The readings the paper leaves open"), and the defaults are chosen from it.
"""
from __future__ import annotations

import dataclasses
from typing import Sequence

import numpy as np

from .runs import MUS, NINE, Run, RunCache, Settings


@dataclasses.dataclass(frozen=True)
class Variant:
    label: str
    settings: Settings
    """The settings that differ from the default configuration."""


VARIANTS: tuple[Variant, ...] = (
    Variant("default", ()),
    Variant("S-curve MSF", (("msf.profile", "scurve"),)),
    Variant("trigger off: a plan through y_safe weighs as a capped one", (("weight.barrier_violated_factor", 0.7),)),
    Variant("kinematic ρ", (("weight.rho_reading", "kinematic"),)),
    Variant("τ, ν at detection", (("weight.nu_reading", "at_detection"),)),
    Variant("ν remaining", (("weight.nu_reading", "remaining"),)),
    Variant("clipped barrier", (("mpc.barrier", "clipped"),)),
    Variant("kinematic ρ, τ and ν at detection", (("weight.rho_reading", "kinematic"),
                                                  ("weight.nu_reading", "at_detection"))),
    Variant("kinematic ρ, ν remaining", (("weight.rho_reading", "kinematic"), ("weight.nu_reading", "remaining"))),
    Variant("kinematic ρ, ν remaining, trigger off", (("weight.rho_reading", "kinematic"),
                                                      ("weight.nu_reading", "remaining"),
                                                      ("weight.barrier_violated_factor", 0.7))),
    Variant("kinematic ρ, τ and ν at detection, trigger off, clipped barrier (the MPC's largest share)",
            (("weight.rho_reading", "kinematic"), ("weight.nu_reading", "at_detection"),
             ("weight.barrier_violated_factor", 0.7), ("mpc.barrier", "clipped"))),
    Variant("S-curve MSF, kinematic ρ, τ and ν at detection, trigger off", (
        ("msf.profile", "scurve"), ("weight.rho_reading", "kinematic"), ("weight.nu_reading", "at_detection"),
        ("weight.barrier_violated_factor", 0.7))),
)
"""The combinations worth showing: the default, each reading changed alone, and the combinations that give the MPC
the largest share (the review of eafd7a4 measured the last)."""


@dataclasses.dataclass(frozen=True)
class VariantRow:
    """The nine paper cases with one variant on one road."""

    variant: Variant
    mu: float
    runs: tuple[Run, ...]


def variant_rows(cache: RunCache, variants: Sequence[Variant] = VARIANTS, mus: Sequence[float] = MUS,
                 cases: Sequence[str] = NINE) -> list[VariantRow]:
    """Each variant's combined runs of ``cases`` on each road of ``mus``."""
    return [VariantRow(v, mu, tuple(cache.run(name, "combined", mu, v.settings) for name in cases))
            for v in variants for mu in mus]


def _short(name: str) -> str:
    return name.removeprefix("paper_")


def render_variants(rows: Sequence[VariantRow]) -> str:
    """The variants table (markdown): per variant and road, over the nine cases, the outcomes, the mean w_MPC
    under the threat (mean over the cases), the total variation of δ and the time at the steering limit (mean
    and largest), the smallest clearance, the lowest speed and the largest lateral offset (with their cases)."""
    lines = ["| variant | settings | μ | outcomes | mean w_MPC | TV δ (rad) mean / max | at the limit (s) mean / max "
             "| least clearance (m) | lowest speed (m/s) | largest abs y (m) |", "|---" * 10 + "|"]
    for row in rows:
        s = [r.summary for r in row.runs]
        outcomes: dict[str, int] = {}
        for x in s:
            outcomes[x["outcome"]] = outcomes.get(x["outcome"], 0) + 1
        tv = [x["steer_total_variation_rad"] for x in s]
        limit = [x["time_at_steer_limit_s"] for x in s]
        clearance = min(s, key=lambda x: x["min_clearance_m"])
        slowest = min(s, key=lambda x: x["min_speed_mps"])
        widest = max(s, key=lambda x: x["max_lateral_offset_m"])
        settings = ", ".join(f"`{k}: {v}`" for k, v in row.variant.settings) or "—"
        lines.append(
            f"| {row.variant.label} | {settings} | {row.mu:g} | "
            + ", ".join(f"{n} {o}" for o, n in sorted(outcomes.items(), key=lambda kv: -kv[1]))
            + f" | {np.mean([x['mean_weight_mpc'] or 0.0 for x in s]):.2f} | {np.mean(tv):.2f} / {max(tv):.2f} | "
            f"{np.mean(limit):.2f} / {max(limit):.2f} | {clearance['min_clearance_m']:.2f} "
            f"({_short(clearance['scenario'])}) | {slowest['min_speed_mps']:.2f} ({_short(slowest['scenario'])}) | "
            f"{widest['max_lateral_offset_m']:.1f} ({_short(widest['scenario'])}) |")
    return "\n".join(lines)
