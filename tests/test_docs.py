"""The docs match the code and stay inside the repository: docs/architecture.md's module maps name every module of
``moose`` and ``moose_ros`` and only those, a package's row names each of its modules, every link of every Markdown
file points to a file of the repository (and to a heading of it, where it names one), every page of docs/ is reached
from the README, the README stays short, and every generator writes to the page that holds its blocks."""
from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path
from types import ModuleType

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


def anchors(path: Path) -> set[str]:
    """The anchors GitHub gives the headings of a Markdown file: lower case, punctuation dropped, spaces as hyphens,
    a repeated one numbered (``-1``, ``-2``); headings inside code fences are not headings."""
    found: set[str] = set()
    fence = False
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.startswith("```"):
            fence = not fence
        heading = None if fence else re.match(r"#{1,6} (.*)", line)
        if heading:
            anchor = re.sub(r"[^\w\- ]", "", heading.group(1).strip().lower()).replace(" ", "-")
            numbered, n = anchor, 0
            while numbered in found:
                n += 1
                numbered = f"{anchor}-{n}"
            found.add(numbered)
    return found


def links(path: Path) -> list[str]:
    """The targets of the Markdown links and images of ``path`` (not in code spans or fences)."""
    text = re.sub(r"```.*?```", "", path.read_text(encoding="utf-8"), flags=re.S)
    text = re.sub(r"`[^`\n]*`", "", text)
    return re.findall(r"\]\(([^)\s]+)\)", text)


@pytest.mark.parametrize("path", markdown_files(), ids=lambda p: str(p.relative_to(ROOT)))
def test_every_link_points_into_the_repository(path: Path) -> None:
    text = path.read_text(encoding="utf-8")
    assert not re.findall(r"https?://(?!127\.0\.0\.1|localhost)[^\s)>`]+", text), "a link outside the repository"
    for target in links(path):
        file, _, anchor = target.partition("#")
        local = (path.parent / file).resolve() if file else path
        assert local.is_relative_to(ROOT) and local.exists(), f"{target} is not a file of the repository"
        if anchor and local.suffix == ".md":
            assert anchor in anchors(local), f"{target}: {local.relative_to(ROOT)} has no heading #{anchor}"


def test_the_anchors_are_githubs() -> None:
    """The anchor rule on headings of these pages (checked against the anchors GitHub renders for them)."""
    page = ROOT / "docs" / "architecture.md"
    assert {"closed-loop-and-rates-lockstep-moosesimulation", "module-map-moose_ros",
            "the-papers-equations-and-figures"} <= anchors(page)


def test_the_readme_is_short_and_reaches_every_page_of_the_docs() -> None:
    """Issue 27: at most 150 lines of at most 200 characters, and every page of docs/ one link away from the README
    or from the index page docs/design.md it links to."""
    readme = ROOT / "README.md"
    lines = readme.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= 150, f"README.md has {len(lines)} lines"
    assert max(len(line) for line in lines) <= 200, [n + 1 for n, line in enumerate(lines) if len(line) > 200]
    reached = {(readme.parent / t.partition("#")[0]).resolve() for t in links(readme)}
    index = ROOT / "docs" / "design.md"
    assert index.resolve() in reached
    reached |= {(index.parent / t.partition("#")[0]).resolve() for t in links(index)}
    pages = {p.resolve() for p in (ROOT / "docs").glob("*.md")}
    assert pages - reached == set(), f"pages no link reaches: {sorted(p.name for p in pages - reached)}"
    topics = ["maps.md", "ros2.md", "vehicle-bus.md", "bags.md", "benchmarks.md", "testing.md"]
    assert {ROOT / "docs" / t for t in topics} <= reached


def generated_blocks(path: Path) -> set[str]:
    return set(re.findall(r"<!-- BEGIN ([\w-]+) -->", path.read_text(encoding="utf-8")))


def test_every_generated_block_is_on_exactly_one_page() -> None:
    where: dict[str, list[str]] = {}
    for path in markdown_files():
        for name in generated_blocks(path):
            where.setdefault(name, []).append(str(path.relative_to(ROOT)))
    assert {name: files for name, files in where.items() if len(files) != 1} == {}


def commands_writing_markdown() -> list[tuple[str, str, list[str]]]:
    """(file, generator, the files it is told to ``--write``) of every generator command in the docs and in the code's
    own help (``moose benchmark``'s ``COMMAND``)."""
    from moose.cli.benchmark import COMMAND

    sources = [(str(p.relative_to(ROOT)), p.read_text(encoding="utf-8")) for p in markdown_files()]
    sources.append(("moose.cli.benchmark.COMMAND", COMMAND))
    found = []
    pattern = re.compile(r"(moose\s+(?:reproduce|budget|benchmark)|moose_ros\.fault_matrix|bench/bench_realtime\.py)"
                         r"((?:\s+(?:--[\w-]+|[\w./-]+))*)")
    for where, text in sources:
        for m in pattern.finditer(text):
            writes = re.findall(r"--write\s+([\w./-]+)", m.group(2))
            if writes:
                found.append((where, re.sub(r"\s+", " ", m.group(1)), writes))
    return found


def test_every_generator_command_in_the_docs_writes_to_pages_that_hold_its_blocks() -> None:
    """Each ``--write FILE`` the docs tell a reader to run names a file that holds one of that generator's blocks
    (the command refuses any other, and a block no command writes would go stale unnoticed)."""
    from moose.cli.budget import GENERATED as BUDGET
    from moose.cli.reproduce import GENERATED as REPRODUCE
    from moose.reproduce import blocks_in

    blocks = {"moose reproduce": REPRODUCE, "moose budget": BUDGET, "moose benchmark": ("leaderboard",),
              "bench/bench_realtime.py": ("realtime",)}
    commands = commands_writing_markdown()
    assert {generator for _, generator, _ in commands} >= {"moose reproduce", "moose budget", "moose benchmark",
                                                           "moose_ros.fault_matrix"}
    written: set[str] = set()
    for where, generator, files in commands:
        for name in files:
            path = ROOT / name
            assert path.is_file(), f"{where}: {generator} --write {name}: no such file"
            if generator in blocks:
                held = blocks_in(path, blocks[generator])
                assert held, f"{where}: {generator} --write {name}: it holds none of {blocks[generator]}"
                written |= set(held)
    every = {name for names in blocks.values() for name in names
             if any(f"<!-- BEGIN {name} -->" in p.read_text(encoding="utf-8") for p in markdown_files())}
    assert every >= set(REPRODUCE) | set(BUDGET) | {"leaderboard"}
    assert written == every, f"blocks no documented command writes: {sorted(every - written)}"


def bench_script(name: str) -> ModuleType:
    """A script of bench/ as a module (registered, so that its dataclasses resolve their annotations)."""
    spec = importlib.util.spec_from_file_location(f"bench_{name}", ROOT / "bench" / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def test_the_fault_matrix_and_the_bench_tables_are_where_their_generators_write() -> None:
    """``python -m moose_ros.fault_matrix --write PAGE`` names its page in its markers; ``bench/mutation.py --docs`` and
    ``bench/test_durations.py --docs`` write the page their ``DOCS`` names: each page holds those markers, and no other
    page does."""
    from moose_ros.fault_matrix import MATRIX_BEGIN, MATRIX_END, WEAKEST_BEGIN, WEAKEST_END

    mutation, durations = bench_script("mutation"), bench_script("test_durations")
    written = [(MATRIX_BEGIN, MATRIX_END, re.search(r"--write (\S+)`", MATRIX_BEGIN).group(1)),
               (WEAKEST_BEGIN, WEAKEST_END, re.search(r"--write (\S+)`", WEAKEST_BEGIN).group(1)),
               (mutation.BEGIN, mutation.END, str(mutation.DOCS.relative_to(ROOT))),
               (f"<!-- BEGIN {durations.BLOCK} -->", f"<!-- END {durations.BLOCK} -->",
                str(durations.DOCS.relative_to(ROOT)))]
    for begin, end, page in written:
        holding = [str(p.relative_to(ROOT)) for p in markdown_files() if begin in p.read_text(encoding="utf-8")]
        assert holding == [page], f"{begin}: on {holding}, written to {page}"
        assert end in (ROOT / page).read_text(encoding="utf-8")


def test_every_equation_label_quoted_is_in_the_table_of_the_papers_equations() -> None:
    """A reader with the printed paper finds every ``eq. (label)`` of the docs and docstrings in docs/architecture.md's
    table of the paper's equations, which gives its printed number."""
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
