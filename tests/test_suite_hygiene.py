"""The suite's own rules, checked on its source: every expected failure names the exception it expects and the
paper claim it records, and no test is skipped or expected to fail without saying why."""
from __future__ import annotations

import ast
from pathlib import Path
from typing import Optional

TESTS = Path(__file__).resolve().parent


def markers(name: str) -> list[tuple[str, int, Optional[ast.Call]]]:
    """Every ``pytest.mark.<name>`` in the test files: (file, line, the call, or None for a bare marker)."""
    found = []
    for path in sorted(TESTS.glob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        calls = {id(n.func): n for n in ast.walk(tree) if isinstance(n, ast.Call)}
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and node.attr == name and isinstance(node.value, ast.Attribute) \
                    and node.value.attr == "mark":
                found.append((path.name, node.lineno, calls.get(id(node))))
    return found


def test_every_xfail_names_its_exception_and_the_paper_claim() -> None:
    for file, line, call in markers("xfail"):
        where = f"{file}:{line}"
        assert call is not None, f"{where}: a bare xfail marker (no raises=, no reason=)"
        keywords = {k.arg: k.value for k in call.keywords}
        assert "raises" in keywords, f"{where}: xfail without raises= counts any crash as the expected failure"
        reason = keywords.get("reason")
        text = "".join(c.value for c in ast.walk(reason) if isinstance(c, ast.Constant) and isinstance(c.value, str)) \
            if reason is not None else ""
        assert "paper claim" in text and "Dodging the Moose" in text, f"{where}: the reason must name the paper claim"
        assert not (keywords.get("strict") is not None and isinstance(keywords["strict"], ast.Constant)
                    and keywords["strict"].value is False), f"{where}: a non-strict xfail hides a claim that is met"


def test_no_unconditional_skip() -> None:
    for file, line, call in markers("skip"):
        assert call is not None and any(k.arg == "reason" for k in call.keywords), f"{file}:{line}: skip without reason"
    for file, line, call in markers("skipif"):
        has_reason = call is not None and any(k.arg == "reason" for k in call.keywords)
        assert has_reason, f"{file}:{line}: skipif without reason"
