"""Data files shipped inside the package (``moose/data``; the repository's ``config/`` links there), and the
folder where what is derived from them and from the code is cached (:func:`cache_dir`).

They are found with :mod:`importlib.resources`, so an installed wheel finds them as a source
checkout does: the default parameter file, the scenarios and the vehicle bus's DBC.
"""
from __future__ import annotations

import os
from importlib.resources import files
from pathlib import Path


def package_folder(package: str, name: str) -> Path:
    """The folder ``name`` inside the installed ``package`` (pip installs packages unzipped, so it is a
    real folder; a zipped import is refused)."""
    folder = files(package).joinpath(name)
    if not isinstance(folder, Path):
        raise RuntimeError(f"{package} is imported from an archive ({folder}): install it with pip")
    return folder


DATA_DIR = package_folder("moose", "data")
"""The package's data folder."""
PARAMETER_FILE = DATA_DIR / "moose.yaml"
"""The default ROS 2 parameter file."""
SCENARIO_DIR = DATA_DIR / "scenarios"
"""The shipped scenarios (the paper's experiments)."""
DBC_FILE = DATA_DIR / "kanon.dbc"
"""The FPEV2-Kanon vehicle bus (500 kbit/s)."""


def cache_dir() -> Path:
    """The machine's cache (``$MOOSE_CACHE_DIR``, default ``~/.cache/moose``): compiled CasADi functions
    (:mod:`moose.ccompile`), maneuver tables (:mod:`moose.maneuver`), the car's CAN hops (:mod:`moose.timing`).
    Each entry's name carries a hash of everything that decides it, so a changed input never finds another's."""
    return Path(os.environ.get("MOOSE_CACHE_DIR", Path.home() / ".cache" / "moose"))
