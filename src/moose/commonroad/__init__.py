"""CommonRoad: a moose test as a CommonRoad scenario and back, an independent judge of every run, and the
literature's criticality measures.

* :mod:`.geometry` — the footprint of the car and the real obstacle behind a danger zone (no CommonRoad
  import: the core uses it without the packages);
* :mod:`.scenario` — a run as a CommonRoad scenario (:func:`~.scenario.write_run`) and a CommonRoad scenario as a
  moose test (:func:`~.scenario.load`), with commonroad-io;
* :mod:`.judge` — commonroad-drivability-checker's collision and road-compliance checks of the footprint,
  beside our verdict (the CoG path in the danger zone), and why they differ where they do;
* :mod:`.criticality` — commonroad-crime's TTC, TTB, TTS, TTK and TTR at the detection instant;
* :mod:`.assess` — both for a run's summary (:func:`moose.metrics.summarize`).

The packages are the optional extra ``commonroad`` (``pip install 'moose-avoidance[commonroad]'``; ``make``
installs it).  This module and :mod:`.geometry` import none of them; the others do, and are imported only
after :func:`require` (or :func:`available`) said they are there.

Identifiers of what a moose file holds (docs/commonroad.md, "CommonRoad"): the lanelets 1, 2, …; the obstacle
:data:`OBSTACLE_ID`; the ego's driven path :data:`EGO_ID` (a dynamic obstacle of type ``car``); its
planning problem :data:`PLANNING_PROBLEM_ID`.
"""
from __future__ import annotations

import importlib.util
from functools import lru_cache

from ..params import ParamError

OBSTACLE_ID = 100
"""Id of the obstacle (a static obstacle) in a scenario written by moose."""
EGO_ID = 200
"""Id of the ego's driven path (a dynamic obstacle, type ``car``, the vehicle's footprint) in a scenario written
by moose; :func:`moose.commonroad.scenario.load` ignores it."""
PLANNING_PROBLEM_ID = 300
"""Id of the planning problem (the ego's state when the obstacle appears; the goal: past the obstacle)."""

PACKAGES = ("commonroad", "commonroad_dc", "commonroad_crime")
"""The import names of commonroad-io, commonroad-drivability-checker and commonroad-crime."""
INSTALL = "pip install 'moose-avoidance[commonroad]'"


@lru_cache(maxsize=1)
def available() -> bool:
    """Whether the three CommonRoad packages can be imported (asked once per process: every run's summary asks)."""
    return all(importlib.util.find_spec(name) is not None for name in PACKAGES)


def require(what: str) -> None:
    """Raise :class:`~moose.params.ParamError` naming ``what`` and the install command unless :func:`available`."""
    missing = [name for name in PACKAGES if importlib.util.find_spec(name) is None]
    if missing:
        raise ParamError(f"{what} needs the CommonRoad packages (missing: {', '.join(missing)}): {INSTALL}")
