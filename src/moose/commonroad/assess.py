"""The CommonRoad part of a run's summary: the drivability checker's verdict beside ours and, when asked,
commonroad-crime's criticality measures; with notes for what is missing (this module imports no CommonRoad package
until the packages are known to be there)."""
from __future__ import annotations

import math
from typing import Any, Optional

import numpy as np

from . import INSTALL, available


def assess(result: Any, verdict: Any, criticality: bool) -> tuple[Optional[dict[str, Any]], Optional[dict[str, float]],
                                                                  dict[str, str]]:
    """The summary's ``commonroad_verdict`` (:mod:`.judge`) and ``criticality`` (:mod:`.criticality`, only when
    asked: it costs seconds) of a run (:class:`moose.simulation.SimulationResult`) judged ``verdict`` by us, and
    notes for what is missing.  Without the packages both are None and the notes say how to install them."""
    not_asked = "not computed: ask with --criticality"
    if not available():
        missing = f"the CommonRoad packages are not installed: {INSTALL}"
        return None, None, {"commonroad_verdict": missing, "criticality": missing if criticality else not_asked}
    from . import judge

    notes: dict[str, str] = {}
    trace = result.trace
    independent: Optional[dict[str, Any]] = None
    finite = np.all([np.isfinite(np.asarray(trace[k], dtype=float)) for k in ("t", "x", "y", "theta", "vx", "vy")],
                    axis=0)
    if np.any(finite):
        independent = judge.compare(trace, result.scenario, result.config.vehicle, verdict).as_dict()
    else:
        notes["commonroad_verdict"] = "no finite sample of the vehicle state to judge"
    measures: Optional[dict[str, float]] = None
    if criticality:  # commonroad-crime takes seconds to import: only when asked
        from . import criticality as crime

        measures = dict(crime.measures(result.scenario, result.config.vehicle))
        for key, value in measures.items():
            if math.isinf(value):
                notes[key] = ("+inf: no maneuver is needed" if value > 0
                              else "-inf: no such maneuver avoids the obstacle")
    else:
        notes["criticality"] = not_asked
    return independent, measures, notes
