"""What the paper reports, as data: its y_max fit, its nine experiments, and the friction that reproduces them.

Reference data for calibration and comparison; the planners never read it.  Light on purpose (the
scenario files resolve ``mu: paper`` through :data:`PAPER_FRICTION` without loading CasADi).
"""
from __future__ import annotations

from typing import NamedTuple, Union

import numpy as np

ArrayLike = Union[float, np.ndarray]

PAPER_FRICTION = 0.33
"""The friction at which the maximum steering maneuver eq. (ymax), integrated for the FPEV2-Kanon with
its steering rate limit (:data:`moose.params.VEHICLE_LIMITS`), gives the ν printed in the paper's
Figs. 7–9 (:func:`moose.calibration.calibrate`: the RMS error over the nine experiments is least at
μ ≈ 0.33, 0.028).  A calibration of the paper's y_max, not a property of any road: the paper never
states μ, and the y_max fit only identifies μ F_z / m.  The paper's scenarios run at this μ
(``mu: paper`` in their files) so that their ν labels hold for the simulated car."""


PAPER_FIT_TERMS: tuple[tuple[float, int, int], ...] = (
    (-0.8001, 0, 0), (0.4752, 1, 0), (2.1603, 0, 1), (-0.0481, 2, 0), (-1.1421, 1, 1),
    (-1.3265, 0, 2), (0.0846, 2, 1), (0.6708, 1, 2), (0.2326, 0, 3), (-0.0183, 2, 2),
    (-0.0592, 1, 3), (-0.0134, 0, 4),
)
"""(coefficient, power of v_x, power of t) of the polynomial ``yego(v, t)`` declared by
``declare function`` in the TikZ code of the paper's Fig. 4, "Maximum steering maneuver"
(label ``fig:path``), copied verbatim."""


def paper_y_max_fit(vx: ArrayLike, t: ArrayLike) -> ArrayLike:
    """The paper's polynomial fit of y_max (m): ``yego(v, t)`` of Fig. 4 ("Maximum steering maneuver").

    First argument v_x (m/s), second t (s): with this order the fit gives the ν
    printed in Figs. 7–9 to two decimals (ν = w / yego(v_des, τ)).  Reference
    data, not used by the planners: the quartic is not 0 at t = 0, dips below 0
    around t = 0.5 s (yego(7, 0.5) < 0) and is flat (non-physical) at
    v_x = 1 m/s; it is meaningful for t ∈ [1, 5] s, v_x ∈ [3, 7] m/s.
    """
    v = np.asarray(vx, dtype=float)
    s = np.asarray(t, dtype=float)
    out = sum(c * v**i * s**j for c, i, j in PAPER_FIT_TERMS)
    return float(out) if np.ndim(out) == 0 else out


class PaperExperiment(NamedTuple):
    """One experiment of Figs. 7–9: speed, τ, far-edge width w of the drawn box, printed ν."""

    vx: float
    tau: float
    w: float
    nu: float
    v_detect: float
    """Speed at detection (m/s): 4.5 in the third 6 m/s case (the text), else vx."""
    figure: str


PAPER_EXPERIMENTS: tuple[PaperExperiment, ...] = (
    PaperExperiment(5.0, 5.0, 4.0, 0.25, 5.0, "fig:exptx5"),
    PaperExperiment(5.0, 4.0, 3.2, 0.26, 5.0, "fig:exptx5"),
    PaperExperiment(5.0, 3.0, 2.4, 0.32, 5.0, "fig:exptx5"),
    PaperExperiment(6.0, 3.0, 2.0, 0.21, 6.0, "fig:exptx6"),
    PaperExperiment(6.0, 3.0, 2.4, 0.26, 6.0, "fig:exptx6"),
    PaperExperiment(6.0, 3.0, 3.2, 0.34, 4.5, "fig:exptx6"),
    PaperExperiment(7.0, 2.8, 2.0, 0.19, 7.0, "fig:exptx7"),
    PaperExperiment(7.0, 2.0, 2.0, 0.40, 7.0, "fig:exptx7"),
    PaperExperiment(7.0, 1.4, 2.0, 0.95, 7.0, "fig:exptx7"),
)
"""The nine experiments of the paper (Figs. 7–9).  The printed ν equals
w / yego(vx, τ) in all nine (the 4.5 m/s case too: its ν was computed at 6 m/s)."""
