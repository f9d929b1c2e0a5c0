"""Criticality maps: many moose tests over axes of speed, τ, width or ν, friction, planner, seed and any
parameter, on local worker processes or a Dask cluster (``moose sweep``).

* :mod:`.axes` — axes (lists, ranges, sampled ranges), grid and Latin-hypercube sampling, :class:`Case`;
* :mod:`.spec` — :class:`SweepSpec`: the sweep, its validated cases (every input checked up front);
* :mod:`.case` — one case: scenario, configuration, run, row; time limits;
* :mod:`.backends` — local worker processes, Dask;
* :mod:`.store` — the run folder: manifest, configuration, journal, ``results.parquet``;
* :mod:`.runner` — run what is not done yet, with a progress bar; Ctrl-C keeps what is done;
* :mod:`.maps` — heat maps, safe-envelope boundaries and the HTML report (``moose sweep plot``).

The results table needs pyarrow and the progress bar rich (``pip install 'moose-avoidance[sweep]'``);
the Dask backend needs ``dask.distributed`` (``moose-avoidance[dask]``).
"""
from .axes import Axis, Case, parse_axis
from .case import run_case
from .spec import SweepSpec

__all__ = ["Axis", "Case", "SweepSpec", "parse_axis", "run_case"]
