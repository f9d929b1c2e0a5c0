"""docs/design.md's module maps match the code: every module of ``moose`` and ``moose_ros`` is in its map,
every module a map names exists, and a package's row names each of its modules."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DESIGN = (ROOT / "docs" / "design.md").read_text(encoding="utf-8")
PACKAGES = {"core": (ROOT / "src" / "moose", "## Module map (core)"),
            "moose_ros": (ROOT / "ros2_ws" / "src" / "moose_ros" / "moose_ros", "Module map of `moose_ros`:")}


def table_after(heading: str) -> dict[str, str]:
    """Module name → the rest of its row, from the first table after ``heading``."""
    text = DESIGN[DESIGN.index(heading):]
    rows: dict[str, str] = {}
    started = False
    for line in text.splitlines()[1:]:
        if line.startswith("|"):
            started = True
            cells = [c.strip() for c in line.strip("|").split("|")]
            for name in re.findall(r"`([^`]+)`", cells[0]):
                rows[name] = " | ".join(cells[1:])
        elif started:
            break
    return rows


def modules(folder: Path) -> set[str]:
    """Modules and packages directly in ``folder`` (private ones and ``__main__`` aside)."""
    return {p.stem for p in folder.glob("*.py") if not p.stem.startswith("_")} | \
        {p.name for p in folder.iterdir() if (p / "__init__.py").is_file()}


@pytest.mark.parametrize("package", sorted(PACKAGES))
def test_the_module_map_names_every_module_and_only_modules(package: str) -> None:
    folder, heading = PACKAGES[package]
    rows = table_after(heading)
    assert modules(folder) - set(rows) == set(), "modules missing from docs/design.md's map"
    assert set(rows) - modules(folder) == set(), "the map names modules that do not exist"


@pytest.mark.parametrize("package", sorted(PACKAGES))
def test_a_packages_row_names_each_of_its_modules(package: str) -> None:
    folder, heading = PACKAGES[package]
    rows = table_after(heading)
    for name in sorted(rows):
        if (folder / name / "__init__.py").is_file():
            named = set(re.findall(r"`([A-Za-z_]+)`", rows[name]))
            missing = modules(folder / name) - named
            assert not missing, f"{package}.{name}: its row does not name {sorted(missing)}"
