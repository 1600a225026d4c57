"""Every Python code block of the documentation runs (issue 38, "docs that run").

Each markdown page under ``docs/`` has its fenced ```` ```python ```` blocks run in order, in
one namespace per page (a module of its own, as a reader pasting the blocks into one session),
in a temporary working folder (so the ``runs/...`` folders the examples write land there). A
traceback names the page and its line. Training examples use budgets of seconds; a block that
cannot be made short (a Ray cluster) is preceded by ``<!-- skip-snippet: REASON -->`` in the
page, and :data:`SKIPPED` lists those pages, so a new skip is a visible choice.
"""

from __future__ import annotations

import importlib.util
import json
import re
import sys
import types
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import NamedTuple

import pytest

from leoc.systems import system_names, unregister_system

pytestmark = pytest.mark.usefixtures("single_thread")

DOCS = Path(__file__).resolve().parents[1] / "docs"
#: Folders under docs/ that hold no hand-written pages (build output, generated gallery).
GENERATED = ("_build", "auto_examples")
FENCE = re.compile(r"^(?P<marker>`{3,}|~{3,})\s*(?P<info>.*)$")
PYTHON = "python"
SKIP_MARKER = re.compile(r"^<!--\s*skip-snippet:\s*(?P<reason>\S.*?)\s*-->$")
#: Pages with a skipped block, and how many (a new skip needs a reason here too).
SKIPPED = {"user_guide/cluster.md": 1}


class Snippet(NamedTuple):
    """A fenced Python block: its page, the page line of its first code line, its code and the
    reason it is skipped (``None``: it runs)."""

    page: Path
    line: int
    code: str
    skip_reason: str | None


def doc_pages() -> list[Path]:
    """The hand-written markdown pages under ``docs/``."""
    return sorted(
        page
        for page in DOCS.rglob("*.md")
        if not any(part in GENERATED for part in page.relative_to(DOCS).parts)
    )


def snippets(page: Path) -> list[Snippet]:
    """The page's fenced blocks whose language is ``python``, in order.

    A fence closes at a line of the same character at least as long (CommonMark); a block
    whose previous non-blank line is a ``skip-snippet`` comment with a reason is marked skipped.
    """
    found: list[Snippet] = []
    lines = page.read_text(encoding="utf-8").splitlines()
    index = 0
    while index < len(lines):
        opening = FENCE.match(lines[index])
        if opening is None:
            index += 1
            continue
        marker, info = opening["marker"], opening["info"].split()
        start = index + 1
        end = start
        while end < len(lines) and not _closes(lines[end], marker):
            end += 1
        if info and info[0] == PYTHON:
            previous = next((text for text in reversed(lines[:index]) if text.strip()), "")
            skip = SKIP_MARKER.match(previous.strip())
            code = "\n".join(lines[start:end]) + "\n"
            found.append(Snippet(page, start + 1, code, skip["reason"] if skip else None))
        index = end + 1
    return found


def _closes(line: str, marker: str) -> bool:
    stripped = line.strip()
    return len(stripped) >= len(marker) and set(stripped) == {marker[0]}


def run_page(page: Path, workdir: Path) -> int:
    """Run the page's blocks (not the skipped ones) in one fresh module, in ``workdir``; return
    how many ran. Systems a page registers are unregistered afterwards."""
    name = "doc_snippets_" + re.sub(r"\W", "_", page.stem)
    module = types.ModuleType(name)
    module.__file__ = str(page)
    # dataclasses look a class's module up in sys.modules (ClassVar under postponed annotations)
    sys.modules[name] = module
    registered = set(system_names())
    ran = 0
    try:
        with _working_directory(workdir):
            for snippet in snippets(page):
                if snippet.skip_reason is not None:
                    continue
                # padded so that tracebacks give the page's own line numbers
                source = "\n" * (snippet.line - 1) + snippet.code
                exec(compile(source, str(page), "exec", dont_inherit=True), module.__dict__)  # noqa: S102
                ran += 1
    finally:
        del sys.modules[name]
        for system in set(system_names()) - registered:
            unregister_system(system)
        if "matplotlib.pyplot" in sys.modules:
            sys.modules["matplotlib.pyplot"].close("all")
    return ran


@contextmanager
def _working_directory(path: Path) -> Iterator[None]:
    import os

    before = Path.cwd()
    os.chdir(path)
    try:
        yield
    finally:
        os.chdir(before)


PAGES = [page for page in doc_pages() if snippets(page)]


@pytest.mark.slow
@pytest.mark.parametrize("page", PAGES, ids=[str(page.relative_to(DOCS)) for page in PAGES])
def test_the_page_s_python_blocks_run(page: Path, tmp_path) -> None:
    expected = sum(snippet.skip_reason is None for snippet in snippets(page))
    assert run_page(page, tmp_path) == expected


def test_every_python_fence_is_collected() -> None:
    """Independent count: every line opening a python fence is a collected block, and no block
    is written in a form the runner would not see (```py, ```{code-block} python, >>>)."""
    for page in doc_pages():
        text = page.read_text(encoding="utf-8")
        openings = re.findall(r"^```python[ \t]*$", text, flags=re.MULTILINE)
        assert len(snippets(page)) == len(openings), page
        others = re.findall(r"^(?:```|~~~).*\b(?:py|python3|pycon|ipython)\b.*$", text, re.M)
        others += re.findall(r"^```\{code[-a-z]*\}\s*python.*$", text, flags=re.MULTILINE)
        assert not others, f"{page}: write Python blocks as ```python so that they run: {others}"


def test_skips_are_few_and_give_a_reason() -> None:
    skipped: dict[str, int] = {}
    for page in doc_pages():
        count = sum(snippet.skip_reason is not None for snippet in snippets(page))
        if count:
            skipped[str(page.relative_to(DOCS))] = count
        for line in page.read_text(encoding="utf-8").splitlines():
            if "skip-snippet" in line:
                assert SKIP_MARKER.match(line.strip()), f"{page}: a skip needs a reason: {line}"
    assert skipped == SKIPPED


def test_the_runner_reports_a_failing_block_at_its_page_line(tmp_path) -> None:
    page = tmp_path / "page.md"
    page.write_text(
        "# A page\n\n```python\nvalue = 1\n```\n\nText.\n\n"
        "<!-- skip-snippet: demonstrates the skip -->\n```python\nraise SystemExit\n```\n\n"
        "```python\nassert value == 1\nvalue = undefined_name\n```\n",
        encoding="utf-8",
    )
    blocks = snippets(page)
    assert [(block.line, block.skip_reason) for block in blocks] == [
        (4, None),
        (11, "demonstrates the skip"),
        (15, None),
    ]
    with pytest.raises(NameError, match="undefined_name") as error:
        run_page(page, tmp_path)
    frame = error.traceback[-1]
    assert (Path(str(frame.path)), frame.lineno + 1) == (page, 16)


def test_the_runner_runs_in_the_working_folder_and_forgets_registrations(tmp_path) -> None:
    page = tmp_path / "page.md"
    page.write_text(
        "```python\nfrom pathlib import Path\n\nPath('written.txt').write_text('x')\n"
        "from leoc.systems import register_system, make_system\n"
        "from leoc.systems.pendulum import Pendulum\n\n"
        "class Copy(Pendulum):\n    name = 'copy_of_pendulum'\n\n"
        "register_system('copy_of_pendulum', Copy)\n```\n",
        encoding="utf-8",
    )
    workdir = tmp_path / "work"
    workdir.mkdir()
    assert run_page(page, workdir) == 1
    assert (workdir / "written.txt").is_file()
    assert "copy_of_pendulum" not in system_names()


ROOT = DOCS.parent
#: A repository path named in leoc's source: help strings, docstrings, comments, messages.
REPOSITORY_PATH = re.compile(r"(?<![\w/.-])(?:docs|benchmarks|scripts|tests)/[\w./-]*\w")


def repository_paths() -> dict[str, list[str]]:
    """Each repository path named in ``src/leoc``, with the ``file:line`` places naming it."""
    named: dict[str, list[str]] = {}
    for source in sorted((ROOT / "src" / "leoc").rglob("*.py")):
        for number, line in enumerate(source.read_text(encoding="utf-8").splitlines(), 1):
            for path in REPOSITORY_PATH.findall(line):
                named.setdefault(path, []).append(f"{source.relative_to(ROOT)}:{number}")
    return named


def test_every_path_leoc_names_exists() -> None:
    """No help text or docstring sends a reader to a missing file (the CLI's help once named
    docs/custom_system.md, which never existed)."""
    named = repository_paths()
    assert "docs/user_guide/custom_system.md" in named  # the scan finds what it is about
    missing = {path: places for path, places in named.items() if not (ROOT / path).exists()}
    assert missing == {}


def test_the_cli_help_names_the_custom_system_guide() -> None:
    from leoc.cli._args import SYSTEM_HELP

    assert "docs/user_guide/custom_system.md" in SYSTEM_HELP


# --- the getting-started page's numbers come from the published studies and the tests -------
GETTING_STARTED = DOCS / "getting_started.md"
STUDIES = ("results/paper", "results/paper-authors")
VARIANT_LABELS = {"leoc": "leoc's defaults", "authors": "the authors' variant"}
SYSTEM_LABELS = {"pendulum": "pendulum", "cartpole": "cart-pole", "mountaincar": "mountain-car"}
KIND_LABELS = {"baseline": "baseline", "hybrid": "hybrid", "hybrid_roa": "ROA hybrid"}
SECONDS_PER_MINUTE = 60


def _page_text(page: Path) -> str:
    """The page with every run of white space one blank (sentences wrap anywhere)."""
    return " ".join(page.read_text(encoding="utf-8").split())


def study_summary(folder: Path) -> str:
    """The page's description of a published study, from its ``meta.json`` and run folders."""
    meta = json.loads((folder / "meta.json").read_text(encoding="utf-8"))
    runs = sorted(folder.glob("runs/*/*/seed*/evaluation.json"))
    seconds = sum(json.loads(run.read_text(encoding="utf-8"))["wall_seconds"] for run in runs)
    seeds = meta["seeds"]
    assert seeds == list(range(seeds[0], seeds[-1] + 1)), seeds  # written as a range
    controllers = meta["controllers"]
    sac = "SAC included" if any(name.startswith("sac_") for name in controllers) else "no SAC"
    jobs, cores = meta["jobs"], meta["machine"]["logical_cpus"]
    minutes = seconds / jobs / SECONDS_PER_MINUTE
    return (
        f"`{folder.relative_to(ROOT).as_posix()}` ({VARIANT_LABELS[meta['variant']]}): "
        f"{len(controllers)} controllers, {sac}, seeds {seeds[0]}-{seeds[-1]}, {len(runs)} runs, "
        f"{seconds:.0f} s of worker time ({minutes:.0f} min on {cores} cores, {jobs} runs at a "
        "time)"
    )


def learning_case_summary(
    system: str, controller: str, budget: int, seeds: int, at_least: int
) -> str:
    """The page's description of one case of ``tests/test_learning.py``."""
    framework, _, kind = controller.partition("_")
    assert budget % 1000 == 0, budget
    return (
        f"{framework.upper()}'s {SYSTEM_LABELS[system]} {KIND_LABELS[kind]} at {budget // 1000}k "
        f"steps on at least {at_least} of seeds 0-{seeds - 1}"
    )


def _learning_cases() -> list[tuple]:
    spec = importlib.util.spec_from_file_location("learning_cases", ROOT / "tests/test_learning.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.CASES


@pytest.mark.parametrize("study", STUDIES)
def test_getting_started_describes_the_published_study(study: str) -> None:
    expected = study_summary(ROOT / study)
    assert expected in _page_text(GETTING_STARTED), f"the page should say: {expected}"


def test_getting_started_states_the_learning_tests_thresholds() -> None:
    page = _page_text(GETTING_STARTED)
    for system, controller, budget, seeds, _measured, at_least in _learning_cases():
        expected = learning_case_summary(system, controller, budget, seeds, at_least)
        assert expected in page, f"the page should say: {expected}"


def test_getting_started_lists_every_command() -> None:
    """The command-line table of the getting-started page has a row for every ``leoc``
    command (``leoc headline`` was once missing from it)."""
    import argparse

    from leoc.cli import build_parser

    parser = build_parser()
    commands = next(
        action for action in parser._actions if isinstance(action, argparse._SubParsersAction)
    )
    page = GETTING_STARTED.read_text(encoding="utf-8")
    missing = [name for name in commands.choices if f"| `leoc {name}" not in page]
    assert missing == []
