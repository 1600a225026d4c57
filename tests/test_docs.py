"""The documentation's docstring rule, without building the site.

``docs/_ext/leoc_api.py`` fails the Sphinx build on a public name without a docstring; this runs
the same check in the test suite (it needs Sphinx: ``pip install -e ".[docs]"``).
"""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

import pytest

pytest.importorskip("sphinx")

EXTENSIONS = Path(__file__).resolve().parents[1] / "docs" / "_ext"


def _checker():
    sys.path.insert(0, str(EXTENSIONS))
    try:
        return importlib.import_module("leoc_api")
    finally:
        sys.path.remove(str(EXTENSIONS))


def test_every_public_name_has_a_docstring() -> None:
    checker = _checker()
    assert checker.missing_docstrings(list(checker.PUBLIC_PACKAGES)) == []
    # the gymnasium adapter is a module of its own (docs/conf.py's extra modules)
    assert checker.missing_docstrings(["leoc.gym_adapter"]) == []


def test_the_check_finds_a_missing_docstring(tmp_path, monkeypatch) -> None:
    package = tmp_path / "undocumented_pkg"
    package.mkdir()
    (package / "__init__.py").write_text(
        '"""A package."""\n\n__all__ = ["LIMIT", "OTHER", "documented", "bare"]\n\n'
        "#: A documented constant.\nLIMIT = 3\nOTHER = 4\n\n\n"
        'def documented():\n    """Has one."""\n\n\ndef bare():\n    pass\n'
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    problems = _checker().missing_docstrings(["undocumented_pkg"])
    assert problems == [
        "undocumented_pkg.OTHER: public constant without a '#:' doc comment",
        "undocumented_pkg.bare: public function without a docstring",
    ]
