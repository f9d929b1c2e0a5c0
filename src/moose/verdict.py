"""The outcome of a moose test, judged from the true vehicle state alone.

:func:`judge` takes sampled ground truth — time, CoG position, yaw and body velocities, as the
plant's trace or the ``/vehicle/odom`` topic of a bag holds them — and the scenario's geometry, and
returns a :class:`Verdict`.  Nothing else enters: not the planners' statuses, not the estimate, not
what a node says about itself, so a verdict can be re-derived from a recorded bag by any reader.

Outcomes (:data:`OUTCOMES`), the first that applies:

1. ``collision`` — the CoG path touches the danger zone (segment-by-segment, so a fast car cannot
   jump over a corner between two samples);
2. ``lost_control`` — the sideslip |β| exceeded ``sideslip_max`` while moving faster than
   ``sideslip_speed_min``, or the heading |θ| exceeded ``heading_max`` (the car turned across the
   road or spun);
3. ``left_field`` — a CoG sample outside the drivable field;
4. ``incomplete`` — the samples do not cover the run: none at all, the first later than
   ``max_gap`` after the start, the last earlier than ``max_gap`` before the planned end, or a
   gap longer than ``max_gap`` in between (a stalled or killed simulator, a dropped stream);
5. ``stopped_short`` — a complete run in which the CoG never passed the zone's far edge (the car
   stopped, or reversed, before the obstacle);
6. ``clear`` — none of these.

A failure the data shows (1–3) is reported even from an incomplete run: what happened, happened.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Literal, Mapping, Optional

import numpy as np

from .schema import VerdictParams
from .signals import Obstacle

Outcome = Literal["clear", "collision", "left_field", "lost_control", "stopped_short", "incomplete"]
OUTCOMES: tuple[Outcome, ...] = ("clear", "collision", "left_field", "lost_control", "stopped_short", "incomplete")
DEFAULT_PARAMS = VerdictParams()


@dataclasses.dataclass(frozen=True)
class Verdict:
    """What :func:`judge` found; every field comes from the samples it was given."""

    outcome: Outcome
    collided: bool
    lost_control: bool
    left_field: bool
    complete: bool
    passed_obstacle: bool
    min_clearance_m: Optional[float]
    """Smallest signed distance of the CoG to the danger zone (m, negative inside); None without samples."""
    max_abs_sideslip_rad: Optional[float]
    """Largest |β| = |atan2(v_y, v_x)| while |v| ≥ ``sideslip_speed_min`` (rad); None if never that fast."""
    max_abs_heading_rad: Optional[float]
    """Largest |θ| (rad); None without samples."""
    reason: str
    """One line that says why (the failing quantity and its threshold, or the coverage gap)."""


def segment_hits_box(x0: float, y0: float, x1: float, y1: float, box: Obstacle) -> bool:
    """Whether the segment from (x0, y0) to (x1, y1) touches the closed box (Liang–Barsky clipping)."""
    t0, t1 = 0.0, 1.0
    dx, dy = x1 - x0, y1 - y0
    for p, q in ((-dx, x0 - box.x_min), (dx, box.x_max - x0), (-dy, y0 - box.y_min), (dy, box.y_max - y0)):
        if p == 0.0:
            if q < 0.0:
                return False
            continue
        r = q / p
        if p < 0.0:
            t0 = max(t0, r)
        else:
            t1 = min(t1, r)
        if t0 > t1:
            return False
    return True


def _near(x: np.ndarray, y: np.ndarray, box: Obstacle) -> list[int]:
    """The segments i (from sample i to i + 1) whose bounding boxes meet the closed ``box``: the only ones that can
    touch it (:func:`segment_hits_box` decides for them)."""
    x0, x1, y0, y1 = x[:-1], x[1:], y[:-1], y[1:]
    near = ((np.minimum(x0, x1) <= box.x_max) & (np.maximum(x0, x1) >= box.x_min)
            & (np.minimum(y0, y1) <= box.y_max) & (np.maximum(y0, y1) >= box.y_min))
    return np.flatnonzero(near).tolist()


def _coverage(t: np.ndarray, end_time: float, max_gap: float) -> Optional[str]:
    """Why the samples do not cover [0, end_time], or None."""
    if t.size == 0:
        return "no samples of the vehicle state"
    if t[0] > max_gap:
        return f"first sample at t = {t[0]:.2f} s (allowed gap {max_gap:g} s)"
    if t[-1] < end_time - max_gap:
        return f"samples end at t = {t[-1]:.2f} s, the run was to end at {end_time:.2f} s"
    gaps = np.diff(t)
    if gaps.size and float(np.max(gaps)) > max_gap:
        i = int(np.argmax(gaps))
        return f"no sample between t = {t[i]:.2f} s and {t[i + 1]:.2f} s (allowed gap {max_gap:g} s)"
    return None


def judge(t: np.ndarray, x: np.ndarray, y: np.ndarray, theta: np.ndarray, vx: np.ndarray, vy: np.ndarray,
          zone: Obstacle, field: Obstacle, end_time: float, params: VerdictParams = DEFAULT_PARAMS) -> Verdict:
    """The verdict of one run from the sampled true state (arrays of equal length, ``t`` increasing).

    ``vx``, ``vy`` are body-frame velocities (``base_link``), ``theta`` the yaw in ``odom``.
    Non-finite (or None) samples count as missing (they never make a run look better).  Samples are
    taken in time order; samples with equal times keep the order given.  A sample on the zone's edge
    touches it: the zone is closed.
    """
    arrays = [np.asarray(a, dtype=float) for a in (t, x, y, theta, vx, vy)]
    if len({a.shape for a in arrays}) != 1 or arrays[0].ndim != 1:
        raise ValueError("t, x, y, theta, vx, vy must be 1-D arrays of equal length")
    ok = np.all(np.isfinite(np.vstack(arrays)), axis=0)
    t, x, y, theta, vx, vy = (a[ok] for a in arrays)
    order = np.argsort(t, kind="stable")
    t, x, y, theta, vx, vy = (a[order] for a in (t, x, y, theta, vx, vy))
    missing = _coverage(t, end_time, params.max_gap)
    if t.size == 0:
        return Verdict("incomplete", False, False, False, False, False, None, None, None, missing or "")
    gap = zone.clearance(x, y)
    hit = bool(np.any(gap <= 0.0)) or any(
        segment_hits_box(float(x[i]), float(y[i]), float(x[i + 1]), float(y[i + 1]), zone) for i in _near(x, y, zone))
    min_clearance = float(np.min(gap))
    if hit:
        min_clearance = min(min_clearance, 0.0)
    speed = np.hypot(vx, vy)
    moving = speed >= params.sideslip_speed_min
    beta = np.abs(np.arctan2(vy[moving], vx[moving]))
    max_beta = float(np.max(beta)) if beta.size else None
    max_heading = float(np.max(np.abs(theta)))
    spun = max_beta is not None and max_beta > params.sideslip_max
    turned = max_heading > params.heading_max
    outside = ~((x >= field.x_min) & (x <= field.x_max) & (y >= field.y_min) & (y <= field.y_max))
    passed = bool(np.any(x > zone.x_max))
    complete = missing is None
    if hit:
        outcome: Outcome = "collision"
        reason = f"the CoG path enters the danger zone (min clearance {min_clearance:.2f} m)"
    elif spun or turned:
        outcome = "lost_control"
        reason = (f"|sideslip| reached {max_beta:.2f} rad (limit {params.sideslip_max:g})" if spun else
                  f"|heading| reached {max_heading:.2f} rad (limit {params.heading_max:.3g})")
    elif bool(np.any(outside)):
        i = int(np.argmax(outside))
        outcome = "left_field"
        reason = f"the CoG left the field at t = {t[i]:.2f} s, ({x[i]:.1f}, {y[i]:.1f}) m"
    elif not complete:
        outcome = "incomplete"
        reason = missing or ""
    elif not passed:
        outcome = "stopped_short"
        reason = f"the CoG never passed the zone's far edge x = {zone.x_max:g} m (reached {float(np.max(x)):.2f} m)"
    else:
        outcome = "clear"
        reason = f"passed with {min_clearance:.2f} m clearance, in control, inside the field"
    return Verdict(outcome, hit, bool(spun or turned), bool(np.any(outside)), complete, passed, min_clearance,
                   max_beta, max_heading, reason)


def limits_of(params: VerdictParams) -> dict[str, float]:
    """The verdict limits of ``params`` by name (the summary's ``verdict_limits``)."""
    return {f.name: float(getattr(params, f.name)) for f in dataclasses.fields(params)}


def changed_limits(limits: Mapping[str, float]) -> str:
    """``""`` when ``limits`` (:func:`limits_of`) are the defaults, else which differ: ``"sideslip_max = 10 instead
    of 0.35"``.  A run judged with other limits can pass where the default verdict fails it."""
    default = limits_of(DEFAULT_PARAMS)
    return ", ".join(f"{name} = {value:g} instead of {default[name]:g}" for name, value in limits.items()
                     if value != default.get(name))


def finite_or_none(value: Optional[float]) -> Optional[float]:
    """``value`` as a float if it is finite, else None (JSON has no NaN or Infinity)."""
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None


# --- exit statuses: what the ``moose`` command (and ``moose_ros``'s plugins) return for a verdict ---------------

EXIT_CLEAR = 0
"""The run was ``clear`` (and, for other commands, everything worked)."""
EXIT_FAILED = 1
"""The run failed: ``collision``, ``left_field``, ``lost_control`` or ``stopped_short``.  Bag tools: the command
ran, but some data could not be read (each loss is reported on stderr)."""
EXIT_BAD_INPUT = 2
"""Bad input (``moose: error: …``): nothing was run."""
EXIT_INCOMPLETE = 3
"""The run is ``incomplete``: its data do not cover it (cut short, a stalled simulator)."""
EXIT_INTERRUPTED = 130
"""Ctrl-C (128 + SIGINT)."""

OUTCOME_EXIT: dict[Outcome, int] = {"clear": EXIT_CLEAR, "collision": EXIT_FAILED, "left_field": EXIT_FAILED,
                                "lost_control": EXIT_FAILED, "stopped_short": EXIT_FAILED,
                                "incomplete": EXIT_INCOMPLETE}
"""The exit status of each outcome of :data:`OUTCOMES` (``moose simulate``, ``moose launch``)."""

EXIT_DEGRADED = 4
"""``moose launch``: the outcome was ``clear``, but the run was degraded — a node failed to start, died, stalled
or was stopped by a fault, or the graph fell back (a planner replaced, a minimum-risk maneuver): the car came
through, the system did not (:mod:`moose_ros.incidents`)."""

EXIT_OUTPUT = 5
"""The command did its work and reported the result (a run's verdict, the cases of a sweep), but an output
could not be written after it (a full disk): ``moose: error: …`` names the output and what was kept.  It takes
precedence over the outcome's status; the outcome is in what was printed."""


def exit_status(outcome: str, degraded: bool = False, interrupted: Optional[str] = None) -> int:
    """The exit status of a run with ``outcome`` (:data:`OUTCOME_EXIT`: 0 clear, 1 a failure, 3 incomplete): 130
    when it was ``interrupted`` by ``"SIGINT"`` (Ctrl-C), and :data:`EXIT_DEGRADED` for a clear run that was
    ``degraded`` (``moose launch``: a node failed, stalled or was replaced by a fallback)."""
    if interrupted == "SIGINT":
        return EXIT_INTERRUPTED
    status = OUTCOME_EXIT[outcome]  # type: ignore[index]
    return EXIT_DEGRADED if status == EXIT_CLEAR and degraded else status
