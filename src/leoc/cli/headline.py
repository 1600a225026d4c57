"""``leoc headline``: the paper's claims, their verdicts in published studies, as a table; or
the trained controllers' proved regions, their robustness scores, or the hybrids' robustness
verdicts, of several studies in one table."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

DEFAULT_STUDIES = (Path("results/paper"), Path("results/paper-authors"))
"""The published studies of the README's claims table, relative to the repository's root."""
CERTIFIED_STUDIES = "results/certified-*"
"""The published studies of the proved-region and robustness tables by default (those with a
report)."""


def add_parser(commands: Any) -> None:
    """Add the ``headline`` command to the subparsers ``commands``."""
    headline = commands.add_parser(
        "headline",
        help="the paper's claims and their verdicts in published studies, as a markdown table",
        description="Read each study's results.json (written by 'leoc plot' or 'leoc publish') "
        "and print one row per claim of the paper: its verdict in each study (holds, partly, "
        "fails, not measured) with the number that decides it, from the report's own checks. "
        "With --proved-regions (or --robustness, --robustness-verdicts), the trained "
        "controllers' proved regions (or robustness scores, or per category whether each "
        "hybrid is at least as robust as its LQR and more than its baseline) of every study "
        "in one table instead. With --write, put the table "
        "between its markers in a markdown file (the README's and the results page's tables "
        "are written so).",
    )
    headline.add_argument(
        "studies",
        type=Path,
        nargs="*",
        metavar="STUDY",
        help="published reproduce folders (default: results/paper results/paper-authors, one "
        f"column each; with a cross-study table every {CERTIFIED_STUDIES} folder "
        "with a report)",
    )
    headline.add_argument(
        "--proved-regions",
        action="store_true",
        help="the proved-region table of the studies (one row per system and controller, a "
        "column naming the study) instead of the claims",
    )
    headline.add_argument(
        "--robustness",
        action="store_true",
        help="the robustness protocol's scores of the studies (one row per system and "
        "controller, columns naming the study and the system) instead of the claims",
    )
    headline.add_argument(
        "--robustness-verdicts",
        action="store_true",
        help="per robustness category, each hybrid's verdict against its LQR (from the "
        "operating region) and against its baseline (every start), one row per study, system "
        "and hybrid, instead of the claims",
    )
    headline.add_argument(
        "--write",
        type=Path,
        action="append",
        metavar="FILE",
        help="a markdown file with the table's begin and end markers ('<!-- headline: begin "
        "...', '<!-- proved regions: begin ...', '<!-- robustness scores: begin ...' or "
        "'<!-- robustness verdicts: begin ...', and "
        "'<!-- ...: end -->'): the table replaces what is between them (repeatable)",
    )
    headline.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from leoc.experiments import headline as tables

    chosen = [name for name in tables.CROSS_STUDY_TABLES if getattr(args, name)]
    if len(chosen) > 1:
        flags = ", ".join("--" + name.replace("_", "-") for name in chosen)
        raise ValueError(f"{flags}: expected one table at a time, found {len(chosen)}")
    if chosen:
        lines_of, begin, end = tables.CROSS_STUDY_TABLES[chosen[0]]
        lines = lines_of(args.studies or certified_studies())
    else:
        lines = tables.headline_lines(args.studies or list(DEFAULT_STUDIES))
        begin, end = tables.BEGIN, tables.END
    if not args.write:
        print("\n".join(lines))
        return 0
    for path in args.write:
        changed = tables.write_headline(path, lines, begin, end)
        print(f"{path}: {'table written' if changed else 'table already current'}")
    return 0


def certified_studies() -> list[Path]:
    """The :data:`CERTIFIED_STUDIES` folders (from the working folder) that have a report."""
    return sorted(
        folder for folder in Path().glob(CERTIFIED_STUDIES) if (folder / "results.json").is_file()
    )
