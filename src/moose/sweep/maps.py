"""Maps of a sweep (``moose sweep plot DIR``): outcome and clearance heat maps, safe envelopes, and where
the combined planner beats either planner alone; PNGs and an HTML report.

Panels are drawn over two axes of the sweep (``x``, ``y``; by default (τ, ν) when both vary, else
(v, τ)), one row per μ and planner, one column per value of every other varied axis (the *facets*,
e.g. the speed).  Seeds of one cell are aggregated conservatively, from the recorded rows alone:

* **outcome** — the most severe outcome among the cell's seeds (:data:`SEVERITY`);
* **clearance** — the smallest ``min_clearance_m`` among them (≤ 0: the path entered the zone);
* **safe** — every seed ``clear`` (passed, no collision, no loss of control, inside the field).

The **safe envelope** of a planner is the boundary between its safe and unsafe cells (the 0.5 contour of
the safe indicator); one panel per μ overlays the three planners.  **Advantage** colours a cell by which
planners are safe there: where the combined planner is safe and MPC alone, MSF alone or both are not.
"""
from __future__ import annotations

import html
import json
import math
from collections import defaultdict
from pathlib import Path
from typing import TYPE_CHECKING, Any, Optional, Sequence

import numpy as np

from ..params import ParamError

if TYPE_CHECKING:
    from matplotlib.typing import LineStyleType

AXES = {
    "speed": ("input.speed_mps", "v (m/s)"), "tau": ("input.tau_s", "τ (s)"), "nu": ("input.nu", "ν (target)"),
    "half_width": ("input.half_width_m", "half width (m)"), "mu": ("input.mu", "μ"),
    "length": ("input.length_m", "length (m)"), "duration": ("input.duration_s", "duration (s)"),
    "field_margin": ("input.field_margin_m", "field margin (m)"), "seed": ("input.seed", "seed"),
    "planner": ("input.planner", "planner"),
}
"""Axis name → (column, label)."""

SEVERITY = ("collision", "lost_control", "left_field", "stopped_short", "incomplete", "crashed", "error", "timeout",
            "clear")
"""Outcomes (and statuses of cases without one), most severe first: a cell shows the first its seeds have."""

COLOURS = {
    "clear": "#2ca02c", "collision": "#d62728", "lost_control": "#9467bd", "left_field": "#ff7f0e",
    "stopped_short": "#8c564b", "incomplete": "#7f7f7f", "crashed": "#bcbd22", "error": "#000000",
    "timeout": "#e377c2",
}
PLANNER_STYLE: dict[str, tuple[str, LineStyleType]] = {
    "combined": ("tab:blue", "-"), "mpc": ("tab:red", "--"), "msf": ("tab:purple", ":"), "aeb": ("tab:gray", "-."),
    "max_steer": ("tab:orange", (0, (5, 1, 1, 1, 1, 1)))}
PAPER_PLANNERS = ("combined", "mpc", "msf")
"""The paper's planners: the advantage map compares the combined planner with the two alone (the baselines are
compared on ``moose benchmark``'s leaderboard)."""
ADVANTAGE = (
    ("beats both", "#1f77b4"), ("beats MPC alone", "#17becf"), ("beats MSF alone", "#aec7e8"),
    ("all safe", "#d9f0d3"), ("combined worse", "#d62728"), ("none safe", "#bdbdbd"),
)
"""Classes of the advantage map: combined safe and both / MPC / MSF alone not; all three safe; the combined
planner unsafe where another is safe; no planner safe."""
FACETS_PER_FIGURE = 6
MAX_FACET_VALUES = 12
"""An axis with more distinct values (a sampled one) is not split into panel columns."""


def _label(row: dict[str, Any]) -> str:
    return str(row.get("outcome")) if row.get("status") == "done" else str(row.get("status"))


def _column(name: str) -> tuple[str, str]:
    if name in AXES:
        return AXES[name]
    if name.startswith("set."):
        return name, name[4:]
    raise ParamError(f"axis {name!r} is unknown: expected one of {sorted(AXES)} or set.GROUP.KEY")


def _varied(rows: Sequence[dict[str, Any]]) -> list[str]:
    names = [n for n in AXES if n not in ("planner", "mu", "seed")]
    names += sorted({k for r in rows for k in r if k.startswith("set.")})
    varied = []
    for name in names:
        column = _column(name)[0]
        if len({json.dumps(r.get(column)) for r in rows}) > 1:
            varied.append(name)
    if "nu" in varied and "half_width" in varied:
        varied.remove("half_width")  # derived from ν (and τ, v, μ)
    return varied


def choose_axes(rows: Sequence[dict[str, Any]], x: Optional[str], y: Optional[str]) -> tuple[str, Optional[str]]:
    """The panel axes: as asked, else (τ, ν), (v, τ) or the first varied axes."""
    varied = _varied(rows)
    for name in (x, y):
        if name is not None:
            _column(name)
            if name not in varied:
                raise ParamError(f"axis {name!r} does not vary in this sweep (varied: {', '.join(varied) or 'none'})")
    if x is not None and y is not None:
        return x, y
    preferred = [("tau", "nu"), ("speed", "tau"), ("tau", "half_width"), ("speed", "nu")]
    for a, b in preferred:
        if a in varied and b in varied and x in (None, a) and y in (None, b):
            return a, b
    rest = [n for n in varied if n not in (x, y)]
    if x is None:
        x = rest.pop(0) if rest else None
    if y is None:
        y = rest.pop(0) if rest else None
    if x is None:
        raise ParamError("the sweep varies no axis besides mu, planner and seed: nothing to map")
    return x, y


class Cells:
    """The rows grouped by (μ, planner, facet) and cell (x, y)."""

    def __init__(self, rows: Sequence[dict[str, Any]], x: str, y: Optional[str]) -> None:
        self.x, self.y = x, y
        varied = [n for n in _varied(rows) if n not in (x, y) and not (n == "half_width" and "nu" in (x, y))]
        distinct = {n: len({json.dumps(r.get(_column(n)[0])) for r in rows}) for n in varied}
        self.facet_axes = [n for n in varied if distinct[n] <= MAX_FACET_VALUES]
        """Axes with a panel column per value."""
        self.projected = [n for n in varied if distinct[n] > MAX_FACET_VALUES]
        """Axes with too many values for columns (sampled ones): their points share the panels."""
        self.xcol = _column(x)[0]
        self.ycol = _column(y)[0] if y else None
        self.groups: dict[tuple, dict[tuple[float, float], list[dict[str, Any]]]] = defaultdict(
            lambda: defaultdict(list))
        for row in rows:
            key = (row["input.mu"], row["input.planner"], self.facet_of(row))
            xy = (float(row[self.xcol]), float(row[self.ycol]) if self.ycol else 0.0)
            self.groups[key][xy].append(row)
        self.mus = sorted({k[0] for k in self.groups})
        order = list(PLANNER_STYLE)
        self.planners = sorted({k[1] for k in self.groups}, key=lambda p: order.index(p) if p in order else 99)
        self.facets = sorted({k[2] for k in self.groups}, key=lambda f: [json.dumps(v) for v in f])
        xs = sorted({xy[0] for g in self.groups.values() for xy in g})
        ys = sorted({xy[1] for g in self.groups.values() for xy in g})
        pairs = {xy for g in self.groups.values() for xy in g}
        self.xs, self.ys = xs, ys
        self.grid = len(xs) <= 200 and len(ys) <= 200 and len(xs) * len(ys) <= 4 * len(pairs)

    def facet_of(self, row: dict[str, Any]) -> tuple:
        return tuple(row.get(_column(n)[0]) for n in self.facet_axes)

    def facet_title(self, facet: tuple) -> str:
        return ", ".join(f"{_column(n)[1]} = {_fmt(v)}" for n, v in zip(self.facet_axes, facet))

    def cells(self, mu: float, planner: str, facet: tuple) -> dict[tuple[float, float], list[dict[str, Any]]]:
        return self.groups.get((mu, planner, facet), {})


def _fmt(value: Any) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)


def worst(rows: Sequence[dict[str, Any]]) -> str:
    labels = {_label(r) for r in rows}
    return next((s for s in SEVERITY if s in labels), sorted(labels)[0])


def safe(rows: Sequence[dict[str, Any]]) -> bool:
    return all(_label(r) == "clear" for r in rows)


def min_clearance(rows: Sequence[dict[str, Any]]) -> float:
    values = [r.get("min_clearance_m") for r in rows]
    finite = [float(v) for v in values if v is not None]
    return min(finite) if finite else math.nan


def _matrix(cells: Cells, cellmap: dict[tuple[float, float], list[dict[str, Any]]], value: Any) -> np.ndarray:
    out = np.full((len(cells.ys), len(cells.xs)), np.nan)
    ix = {v: i for i, v in enumerate(cells.xs)}
    iy = {v: i for i, v in enumerate(cells.ys)}
    for (x, y), rows in cellmap.items():
        out[iy[y], ix[x]] = value(rows)
    return out


def _edges(values: Sequence[float]) -> np.ndarray:
    v = np.asarray(values, dtype=float)
    if v.size == 1:
        return np.array([v[0] - 0.5, v[0] + 0.5])
    mid = 0.5 * (v[1:] + v[:-1])
    return np.concatenate([[v[0] - (mid[0] - v[0])], mid, [v[-1] + (v[-1] - mid[-1])]])


def _panel(ax: Any, cells: Cells, cellmap: dict, value: Any, cmap: Any, norm: Any) -> Any:
    if not cellmap:
        ax.text(0.5, 0.5, "no cases", transform=ax.transAxes, ha="center", va="center", fontsize=7)
        return None
    if cells.grid:
        z = _matrix(cells, cellmap, value)
        return ax.pcolormesh(_edges(cells.xs), _edges(cells.ys), np.ma.masked_invalid(z), cmap=cmap, norm=norm)
    pts = list(cellmap.items())
    return ax.scatter([p[0][0] for p in pts], [p[0][1] for p in pts], c=[value(p[1]) for p in pts], cmap=cmap,
                      norm=norm, s=14, edgecolors="none")


def _figure(rows_n: int, cols_n: int) -> tuple[Any, np.ndarray]:
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(rows_n, cols_n, figsize=(2.4 * cols_n + 1.4, 1.9 * rows_n + 1.2), squeeze=False,
                             sharex=True, sharey=True, layout="constrained")
    return fig, axes


def _decorate(cells: Cells, axes: np.ndarray, row_titles: Sequence[str], facets: Sequence[tuple]) -> None:
    for j, facet in enumerate(facets):
        if cells.facet_axes:
            axes[0, j].set_title(cells.facet_title(facet), fontsize=8)
        axes[-1, j].set_xlabel(_column(cells.x)[1], fontsize=8)
    for i, title in enumerate(row_titles):
        axes[i, 0].set_ylabel(f"{title}\n{_column(cells.y)[1] if cells.y else ''}", fontsize=8)
    for ax in axes.flat:
        ax.tick_params(labelsize=7)


def _save(fig: Any, path: Path) -> Path:
    import matplotlib.pyplot as plt

    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def _mu_label(mu: float) -> str:
    from ..paper import PAPER_FRICTION

    return f"μ = {mu:g}" + (" (paper)" if abs(mu - PAPER_FRICTION) < 1e-12 else "")


def outcome_map(cells: Cells, facets: Sequence[tuple], path: Path) -> Path:
    from matplotlib.colors import BoundaryNorm, ListedColormap
    from matplotlib.patches import Patch

    cmap = ListedColormap([COLOURS[s] for s in SEVERITY])
    norm = BoundaryNorm(np.arange(len(SEVERITY) + 1) - 0.5, len(SEVERITY))
    combos = [(mu, p) for mu in cells.mus for p in cells.planners]
    fig, axes = _figure(len(combos), len(facets))
    seen: set[str] = set()
    for i, (mu, planner) in enumerate(combos):
        for j, facet in enumerate(facets):
            cellmap = cells.cells(mu, planner, facet)
            seen.update(worst(r) for r in cellmap.values())
            _panel(axes[i, j], cells, cellmap, lambda r: SEVERITY.index(worst(r)), cmap, norm)
    _decorate(cells, axes, [f"{p}, {_mu_label(mu)}" for mu, p in combos], facets)
    fig.legend(handles=[Patch(color=COLOURS[s], label=s) for s in SEVERITY if s in seen], loc="outside lower center",
               ncol=min(len(seen), 5), fontsize=8, frameon=False)
    fig.suptitle("outcome (most severe over seeds)", fontsize=9)
    return _save(fig, path)


def clearance_map(cells: Cells, facets: Sequence[tuple], path: Path) -> Path:
    from matplotlib.colors import TwoSlopeNorm

    values = [min_clearance(r) for g in cells.groups.values() for r in g.values()]
    finite = [v for v in values if math.isfinite(v)]
    low = min(min(finite, default=-1.0), -0.01)
    high = max(max(finite, default=1.0), 0.01)
    norm = TwoSlopeNorm(vmin=low, vcenter=0.0, vmax=high)
    combos = [(mu, p) for mu in cells.mus for p in cells.planners]
    fig, axes = _figure(len(combos), len(facets))
    mappable = None
    for i, (mu, planner) in enumerate(combos):
        for j, facet in enumerate(facets):
            mappable = (_panel(axes[i, j], cells, cells.cells(mu, planner, facet), min_clearance, "RdYlGn", norm)
                        or mappable)
    _decorate(cells, axes, [f"{p}, {_mu_label(mu)}" for mu, p in combos], facets)
    if mappable is not None:
        fig.colorbar(mappable, ax=axes, shrink=0.6, label="min clearance (m, ≤ 0: collision)")
    fig.suptitle("minimum clearance to the danger zone (smallest over seeds)", fontsize=9)
    return _save(fig, path)


def _safe_grid(cells: Cells, cellmap: dict) -> np.ndarray:
    return _matrix(cells, cellmap, lambda r: 1.0 if safe(r) else 0.0)


def envelope_map(cells: Cells, facets: Sequence[tuple], path: Path, paper: Sequence[dict[str, Any]]) -> Path:
    from matplotlib.colors import BoundaryNorm, ListedColormap
    from matplotlib.lines import Line2D

    background, bounds = ListedColormap(["#cfcfcf", "#e5f5e0"]), BoundaryNorm([-0.5, 0.5, 1.5], 2)
    fig, axes = _figure(len(cells.mus), len(facets))
    for i, mu in enumerate(cells.mus):
        for j, facet in enumerate(facets):
            ax = axes[i, j]
            for planner in cells.planners:
                colour, style = PLANNER_STYLE.get(planner, ("k", "-"))
                cellmap = cells.cells(mu, planner, facet)
                if not cellmap:
                    continue
                if planner == "combined" or len(cells.planners) == 1:
                    _panel(ax, cells, cellmap, lambda r: 1.0 if safe(r) else 0.0, background, bounds)
                _boundary(ax, cells, cellmap, colour, style)
            for point in paper:
                if _on_panel(point, cells, mu, facet):
                    ax.plot(point["x"], point["y"], marker="*", color="gold", markeredgecolor="k", markersize=9)
    _decorate(cells, axes, [_mu_label(mu) for mu in cells.mus], facets)
    handles = [Line2D([], [], color=PLANNER_STYLE.get(p, ("k", "-"))[0], linestyle=PLANNER_STYLE.get(p, ("k", "-"))[1],
                      label=f"{p}: safe-envelope boundary") for p in cells.planners]
    if paper:
        handles.append(Line2D([], [], marker="*", color="gold", markeredgecolor="k", linestyle="",
                              label="paper's experiment"))
    fig.legend(handles=handles, loc="outside lower center", ncol=2, fontsize=8, frameon=False)
    fig.suptitle("safe envelope (outcome clear for every seed; pale green: the combined planner's safe cells, "
                 "grey: not)", fontsize=9)
    return _save(fig, path)


def _boundary(ax: Any, cells: Cells, cellmap: dict, colour: str, style: LineStyleType) -> None:
    """The edges between a planner's safe and unsafe cells (on a grid), or the 0.5 contour of the safe
    indicator over the samples (scattered points)."""
    if cells.grid:
        from matplotlib.collections import LineCollection

        z = _safe_grid(cells, cellmap)
        xe, ye = _edges(cells.xs), _edges(cells.ys)
        segments = []
        for i in range(z.shape[0]):
            for j in range(z.shape[1]):
                if j + 1 < z.shape[1] and {z[i, j], z[i, j + 1]} == {0.0, 1.0}:
                    segments.append([(xe[j + 1], ye[i]), (xe[j + 1], ye[i + 1])])
                if i + 1 < z.shape[0] and {z[i, j], z[i + 1, j]} == {0.0, 1.0}:
                    segments.append([(xe[j], ye[i + 1]), (xe[j + 1], ye[i + 1])])
        if segments:
            ax.add_collection(LineCollection(segments, colors=colour, linestyles=style, linewidths=1.8))
    elif len(cellmap) >= 3:
        pts = list(cellmap.items())
        z = np.array([1.0 if safe(r) else 0.0 for _, r in pts])
        if 0.0 < z.mean() < 1.0:
            try:
                ax.tricontour([p[0][0] for p in pts], [p[0][1] for p in pts], z, levels=[0.5], colors=[colour],
                              linestyles=[style], linewidths=1.4)
            except (ValueError, RuntimeError):
                pass  # a degenerate triangulation (collinear samples): no boundary to draw


def advantage_map(cells: Cells, facets: Sequence[tuple], path: Path) -> Optional[Path]:
    paper = [p for p in cells.planners if p in PAPER_PLANNERS]
    if "combined" not in paper or len(paper) < 2:
        return None
    from matplotlib.colors import BoundaryNorm, ListedColormap
    from matplotlib.patches import Patch

    names = [n for n, _ in ADVANTAGE]
    cmap = ListedColormap([c for _, c in ADVANTAGE])
    norm = BoundaryNorm(np.arange(len(ADVANTAGE) + 1) - 0.5, len(ADVANTAGE))
    fig, axes = _figure(len(cells.mus), len(facets))
    for i, mu in enumerate(cells.mus):
        for j, facet in enumerate(facets):
            maps = {p: cells.cells(mu, p, facet) for p in paper}
            merged = {xy: {p: maps[p].get(xy) for p in maps} for xy in maps["combined"]}

            def klass(by_planner: dict[str, Any]) -> float:
                ok = {p: rows is not None and safe(rows) for p, rows in by_planner.items()}
                others = [p for p in ok if p != "combined"]
                if ok["combined"]:
                    beaten = [p for p in others if not ok[p]]
                    if not beaten:
                        return names.index("all safe")
                    if len(beaten) == len(others) and len(others) > 1:
                        return names.index("beats both")
                    return names.index("beats MPC alone" if "mpc" in beaten else "beats MSF alone")
                return names.index("combined worse" if any(ok[p] for p in others) else "none safe")

            _panel(axes[i, j], cells, merged, klass, cmap, norm)
    _decorate(cells, axes, [_mu_label(mu) for mu in cells.mus], facets)
    fig.legend(handles=[Patch(color=c, label=n) for n, c in ADVANTAGE], loc="outside lower center", ncol=3,
               fontsize=8, frameon=False)
    fig.suptitle("where the combined planner is safe and the planners alone are not", fontsize=9)
    return _save(fig, path)


def paper_points(cells: Cells) -> list[dict[str, Any]]:
    """The paper's nine experiments in the sweep's coordinates, with the nearest cell's outcome per planner
    at the paper calibration's μ (empty when the sweep has not that μ, or not the axes τ and ν)."""
    from ..paper import PAPER_EXPERIMENTS, PAPER_FRICTION

    mus = [mu for mu in cells.mus if abs(mu - PAPER_FRICTION) < 1e-12]
    if (not mus or cells.y is None or {cells.x, cells.y} != {"tau", "nu"} or any(n != "speed" for n in cells.facet_axes)
            or cells.projected):
        return []
    points = []
    for e in PAPER_EXPERIMENTS:
        coords = {"tau": e.tau, "nu": e.nu}
        x, y = coords[cells.x], coords[cells.y]
        facet = min(cells.facets, key=lambda f: abs(f[0] - e.v_detect)) if cells.facet_axes else ()
        outcomes = {}
        nearest = None
        for planner in cells.planners:
            cellmap = cells.cells(mus[0], planner, facet)
            if not cellmap:
                continue
            xy = min(cellmap, key=lambda c: ((c[0] - x) / _span(cells.xs)) ** 2 + ((c[1] - y) / _span(cells.ys)) ** 2)
            nearest = xy
            outcomes[planner] = worst(cellmap[xy])
        points.append({"experiment": f"v = {e.v_detect:g} m/s, τ = {e.tau:g} s, w = {e.w:g} m, ν = {e.nu:g}",
                       "x": x, "y": y, "facet": facet, "mu": mus[0], "nearest": nearest, "outcomes": outcomes,
                       "v_detect": e.v_detect})
    return points


def _span(values: Sequence[float]) -> float:
    return (max(values) - min(values)) or 1.0


def _on_panel(point: dict[str, Any], cells: Cells, mu: float, facet: tuple) -> bool:
    if abs(point["mu"] - mu) > 1e-12 or point["facet"] != facet:
        return False
    return not cells.facet_axes or abs(facet[0] - point["v_detect"]) < 1e-9


def draw_maps(folder: Path, out: Path, x: Optional[str] = None, y: Optional[str] = None) -> Path:
    """Draw every map of the sweep in ``folder`` into ``out``; returns the HTML report's path."""
    import matplotlib

    matplotlib.use("Agg")
    from .store import RunFolder, read_results

    folder = Path(folder)
    rows = read_results(folder).to_pylist()
    if not rows:
        raise ParamError(f"{str(folder)!r} holds no finished cases to map")
    manifest = RunFolder(folder).manifest() if folder.is_dir() else None
    check_default_limits(rows, manifest, str(folder))
    x, y = choose_axes(rows, x, y)
    cells = Cells(rows, x, y)
    out.mkdir(parents=True, exist_ok=True)
    points = paper_points(cells)
    figures: list[tuple[str, Path]] = []
    chunks = [cells.facets[i:i + FACETS_PER_FIGURE] for i in range(0, len(cells.facets), FACETS_PER_FIGURE)]
    for k, facets in enumerate(chunks):
        suffix = f"_{k + 1}" if len(chunks) > 1 else ""
        envelope = envelope_map(cells, facets, out / f"envelope{suffix}.png", points)
        figures.append(("Safe envelope per planner", envelope))
        advantage = advantage_map(cells, facets, out / f"advantage{suffix}.png")
        if advantage is not None:
            figures.append(("Where the combined planner beats MPC alone and MSF alone", advantage))
        figures.append(("Outcome", outcome_map(cells, facets, out / f"outcome{suffix}.png")))
        figures.append(("Minimum clearance", clearance_map(cells, facets, out / f"clearance{suffix}.png")))
    measures = criticality_map(rows, out / "criticality.png")
    if measures is not None:
        figures.append(("ν and τ against the literature's criticality measures (commonroad-crime)", measures))
    return write_report(out / "index.html", rows, cells, figures, points, manifest)


MEASURES = (("ttc_s", "TTC"), ("ttb_s", "TTB"), ("tts_s", "TTS"), ("ttk_s", "TTK"), ("ttr_s", "TTR"))
"""commonroad-crime's measures the criticality map plots ν and τ against (row columns ``criticality.<key>``)."""


def criticality_map(rows: Sequence[dict[str, Any]], path: Path) -> Optional[Path]:
    """ν and τ (as the detector measured them) against commonroad-crime's TTC, TTB, TTS, TTK and TTR, one point per
    situation (friction, speed, τ, width, length: its planners and seeds share the measures), coloured by μ; None
    when the rows carry no measures (a sweep without ``--criticality``).  A measure that is ±∞ ("never needed", "no
    such maneuver avoids it": null in the row) has no point; each panel says how many situations it lacks."""
    keyed = [r for r in rows if r.get("status") == "done" and f"criticality.{MEASURES[0][0]}" in r]
    if not keyed:
        return None
    import matplotlib.pyplot as plt

    situations: dict[tuple, dict[str, Any]] = {}
    for r in keyed:
        situation = tuple(r.get(c) for c in ("input.mu", "input.speed_mps", "input.tau_s", "input.half_width_m",
                                             "input.length_m"))
        situations.setdefault(situation, r)
    points = list(situations.values())
    mus = sorted({float(p["input.mu"]) for p in points})
    colours = plt.get_cmap("viridis")(np.linspace(0.1, 0.85, max(len(mus), 1)))
    fig, axes = plt.subplots(2, len(MEASURES), figsize=(3.0 * len(MEASURES), 6.0), squeeze=False,
                             layout="constrained")
    for j, (key, label) in enumerate(MEASURES):
        for i, (column, name) in enumerate((("nu", "ν (detector)"), ("tau_s", "τ (detector), s"))):
            ax = axes[i, j]
            missing = 0
            for mu, colour in zip(mus, colours):
                here = [p for p in points if float(p["input.mu"]) == mu]
                xy = [(p[f"criticality.{key}"], p[column]) for p in here]
                shown = [(x, y) for x, y in xy if x is not None and y is not None]
                missing += len(xy) - len(shown)
                if shown:
                    ax.scatter(*zip(*shown), s=9, color=colour, alpha=0.8, label=f"μ = {mu:g}")
            ax.set(xlabel=f"{label} (s)", ylabel=name if j == 0 else None,
                   title=f"{label}" + (f" ({missing} at ±∞)" if missing else ""))
            ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7)
    fig.suptitle(f"the paper's ν and τ against commonroad-crime's measures at detection ({len(points)} situations)",
                 fontsize=9)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def check_default_limits(rows: Sequence[dict[str, Any]], manifest: Optional[dict[str, Any]], where: str) -> None:
    """Refuse rows that were not judged with the default verdict limits: a map, like the claims table, shows the
    default verdict (a lost control judged a pass under a looser ``sideslip_max`` would colour a cell safe).

    Each row records its limits (``verdict_limits_default``); rows recorded before it did are judged by the
    sweep's configuration in the manifest and its axes (no ``verdict.*`` axis)."""
    from ..verdict import changed_limits

    done = [row for row in rows if row.get("status") == "done"]
    other = [row for row in done if row.get("verdict_limits_default") is False]
    if other:
        raise ParamError(f"{where!r}: {len(other)} cases were judged with other verdict limits "
                         f"({changed_limits(json.loads(other[0]['verdict_limits']))}); maps show the default verdict: "
                         "sweep again without changing the verdict group")
    if all(row.get("verdict_limits_default") is not None for row in done):
        return
    spec = (manifest or {}).get("spec", {})
    verdict = spec.get("config", {}).get("/**", {}).get("ros__parameters", {}).get("verdict")
    varied = [axis for axis in spec.get("axes", {}) if axis.startswith("verdict.")]
    if verdict is None or varied or changed_limits(verdict):
        raise ParamError(f"{where!r}: its rows do not record their verdict limits, and its manifest does not show the "
                         "default ones; maps show the default verdict: sweep again")


def outcome_table(rows: Sequence[dict[str, Any]]) -> list[tuple[float, str, dict[str, int], int]]:
    """(μ, planner, counts of each outcome or status, safe cells) for the report."""
    counts: dict[tuple[float, str], dict[str, int]] = defaultdict(lambda: defaultdict(int))
    for row in rows:
        counts[(row["input.mu"], row["input.planner"])][_label(row)] += 1
    return [(mu, planner, dict(c), sum(c.values())) for (mu, planner), c in sorted(counts.items())]


def write_report(path: Path, rows: Sequence[dict[str, Any]], cells: Cells, figures: Sequence[tuple[str, Path]],
                 points: Sequence[dict[str, Any]], manifest: Optional[dict[str, Any]]) -> Path:
    esc = html.escape
    parts = ["<!doctype html><html><head><meta charset='utf-8'><title>moose sweep</title>",
             "<style>body{font-family:sans-serif;max-width:1400px;margin:1em auto;padding:0 1em}"
             "table{border-collapse:collapse;font-size:13px}td,th{border:1px solid #ccc;padding:2px 6px;"
             "text-align:right}th{background:#eee}img{max-width:100%;border:1px solid #ddd}"
             "code{background:#f4f4f4}</style></head><body>",
             "<h1>moose sweep</h1>"]
    if manifest:
        spec = manifest.get("spec", {})
        axes = ", ".join(f"{k} = {json.dumps(v)}" for k, v in spec.get("axes", {}).items())
        parts.append(f"<p>{manifest.get('recorded', len(rows))} of {manifest.get('cases')} cases; spec "
                     f"<code>{esc(str(manifest.get('spec_hash')))}</code>; sampling {esc(str(spec.get('sampling')))}"
                     f" (seed {esc(str(spec.get('sampling_seed')))}); code {esc(json.dumps(manifest.get('code')))}</p>"
                     f"<p>axes: <code>{esc(axes)}</code></p>")
    parts.append(f"<p>Panels: x = {esc(_column(cells.x)[1])}, y = {esc(_column(cells.y)[1] if cells.y else '-')}; "
                 f"columns: {esc(', '.join(cells.facet_axes) or 'one')}"
                 + (f"; sampled axes shown in the same panels: {esc(', '.join(cells.projected))}"
                    if cells.projected else "")
                 + ". A cell aggregates its seeds: the most severe "
                 "outcome, the smallest clearance; it is safe when every seed is <i>clear</i> (passed the obstacle "
                 "without collision and without loss of control, inside the field).</p>")
    labels = [s for s in SEVERITY if any(_label(r) == s for r in rows)]
    parts.append("<h2>Outcomes</h2><table><tr><th>μ</th><th>planner</th>"
                 + "".join(f"<th>{esc(s)}</th>" for s in labels) + "<th>cases</th></tr>")
    for mu, planner, counts, total in outcome_table(rows):
        parts.append(f"<tr><td>{mu:g}</td><td>{esc(planner)}</td>"
                     + "".join(f"<td>{counts.get(s, 0)}</td>" for s in labels) + f"<td>{total}</td></tr>")
    parts.append("</table>")
    if points:
        parts.append("<h2>The paper's nine experiments on the map</h2><p>Nearest cell at the paper calibration "
                     f"(μ = {points[0]['mu']:g}) and the nearest speed of the sweep; outcome per planner.</p>"
                     "<table><tr><th>experiment</th><th>nearest cell</th>"
                     + "".join(f"<th>{esc(p)}</th>" for p in cells.planners) + "</tr>")
        for p in points:
            where = cells.facet_title(p["facet"])
            if p["nearest"] is not None and cells.y is not None:
                where += f", {_column(cells.x)[1]} = {p['nearest'][0]:g}, {_column(cells.y)[1]} = {p['nearest'][1]:g}"
            parts.append(f"<tr><td>{esc(p['experiment'])}</td><td>{esc(where)}</td>"
                         + "".join(f"<td>{esc(p['outcomes'].get(pl, '-'))}</td>" for pl in cells.planners) + "</tr>")
        parts.append("</table>")
    for title, figure in figures:
        parts.append(f"<h2>{esc(title)}</h2><img src='{esc(figure.name)}' alt='{esc(title)}'>")
    parts.append("</body></html>")
    path.write_text("\n".join(parts) + "\n", encoding="utf-8")
    return path
