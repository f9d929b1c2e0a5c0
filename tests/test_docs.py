"""The docs match the code and stay inside the repository: docs/architecture.md's module maps name every module of
``moose`` and ``moose_ros`` and only those, a package's row names each of its modules, and every link of
every Markdown file points to a file of the repository."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ARCHITECTURE = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
PACKAGES = {"core": (ROOT / "src" / "moose", "## Module map (core)"),
            "moose_ros": (ROOT / "ros2_ws" / "src" / "moose_ros" / "moose_ros", "## Module map (`moose_ros`)")}


def table_after(heading: str) -> dict[str, str]:
    """Module name → the rest of its row, from the first table after ``heading``."""
    text = ARCHITECTURE[ARCHITECTURE.index(heading):]
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
    assert modules(folder) - set(rows) == set(), "modules missing from docs/architecture.md's map"
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


def markdown_files() -> list[Path]:
    skip = {".git", ".venv", ".venv-ros", "runs", "node_modules", ".pytest_cache"}
    return sorted(p for p in ROOT.rglob("*.md") if not skip & set(p.relative_to(ROOT).parts))


@pytest.mark.parametrize("path", markdown_files(), ids=lambda p: str(p.relative_to(ROOT)))
def test_every_link_points_into_the_repository(path: Path) -> None:
    text = path.read_text(encoding="utf-8")
    assert not re.findall(r"https?://(?!127\.0\.0\.1|localhost)[^\s)>`]+", text), "a link outside the repository"
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        local = (path.parent / target.split("#")[0]).resolve()
        assert local.is_relative_to(ROOT) and local.exists(), f"{target} is not a file of the repository"


def test_every_equation_label_quoted_is_in_the_table_of_the_papers_equations() -> None:
    """A reader with the printed paper finds every ``eq. (label)`` of the docs and docstrings in
    docs/architecture.md's table of the paper's equations, which gives its printed number."""
    start = ARCHITECTURE.index("## The paper's equations and figures")
    table = ARCHITECTURE[start:ARCHITECTURE.index("\nFigures:", start)]
    listed = set(re.findall(r"\(([A-Za-z]+)\)", "".join(line.split("|")[1] for line in table.splitlines()
                                                       if line.startswith("| ("))))
    quoted: dict[str, str] = {}
    files = [*markdown_files(), *sorted((ROOT / "src").rglob("*.py")), *sorted((ROOT / "ros2_ws").rglob("*.py"))]
    pattern = re.compile(r"eqs?\. (\([A-Za-z]+\)(?:,? (?:and )?\([A-Za-z]+\))*)")
    for path in files:
        for group in pattern.findall(path.read_text(encoding="utf-8")):
            for label in re.findall(r"\(([A-Za-z]+)\)", group):
                quoted.setdefault(label, str(path.relative_to(ROOT)))
    quoted.pop("label", None)  # the convention's own placeholder
    assert {"skin", "ysafe", "planmpc", "FBL"} <= set(quoted)  # the search finds what it is for
    missing = {label: where for label, where in quoted.items() if label not in listed}
    assert not missing, f"labels quoted but not in docs/architecture.md's table of the paper's equations: {missing}"
