"""The house's rules that a reader checks by eye, checked here: functions short enough to read
at once (issue 39: every function under 60 lines, docstring included)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SOURCE = Path(__file__).resolve().parents[1] / "src" / "leoc"
MAX_FUNCTION_LINES = 59
"""A function's lines from ``def`` (its first decorator aside) to its last line, at most."""


def _functions(path: Path) -> list[tuple[str, int, int]]:
    """``(qualified name, first line, line count)`` of every function and method in ``path``."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    found = []

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                name = f"{prefix}{child.name}"
                found.append((name, child.lineno, child.end_lineno - child.lineno + 1))
                visit(child, f"{name}.")
            elif isinstance(child, ast.ClassDef):
                visit(child, f"{prefix}{child.name}.")

    visit(tree, "")
    return found


def test_the_counter_counts_a_function_from_def_to_its_last_line(tmp_path) -> None:
    sample = tmp_path / "sample.py"
    body = "\n".join(f"    x{i} = {i}" for i in range(5))
    sample.write_text(
        f"@decorated\ndef f():\n    '''doc'''\n{body}\n\nclass C:\n    def g(self):\n        pass\n"
    )
    assert _functions(sample) == [("f", 2, 7), ("C.g", 11, 2)]


@pytest.mark.parametrize(
    "path", sorted(SOURCE.rglob("*.py")), ids=lambda p: str(p.relative_to(SOURCE))
)
def test_every_function_is_short_enough_to_read_at_once(path: Path) -> None:
    long = [
        f"{name} (line {line}): {count} lines"
        for name, line, count in _functions(path)
        if count > MAX_FUNCTION_LINES
    ]
    assert not long, f"{path.relative_to(SOURCE)}: over {MAX_FUNCTION_LINES} lines: {long}"
