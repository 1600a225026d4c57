"""``leoc headline``: the paper's claims, their verdicts in published studies, as a table."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

DEFAULT_STUDIES = (Path("results/paper"), Path("results/paper-authors"))
"""The published studies of the repository's README, relative to its root."""


def add_parser(commands: Any) -> None:
    """Add the ``headline`` command to the subparsers ``commands``."""
    headline = commands.add_parser(
        "headline",
        help="the paper's claims and their verdicts in published studies, as a markdown table",
        description="Read each study's results.json (written by 'leoc plot' or 'leoc publish') "
        "and print one row per claim of the paper: its verdict in each study (holds, partly, "
        "fails, not measured) with the number that decides it, from the report's own checks. "
        "With --write, put the table between the headline markers of a markdown file instead "
        "(the README's table is written so).",
    )
    headline.add_argument(
        "studies",
        type=Path,
        nargs="*",
        default=list(DEFAULT_STUDIES),
        metavar="STUDY",
        help="published reproduce folders, one column each (default: results/paper "
        "results/paper-authors)",
    )
    headline.add_argument(
        "--write",
        type=Path,
        action="append",
        metavar="FILE",
        help="a markdown file with the lines '<!-- headline: begin ... -->' and '<!-- "
        "headline: end -->': the table replaces what is between them (repeatable)",
    )
    headline.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from leoc.experiments.headline import headline_lines, write_headline

    lines = headline_lines(args.studies)
    if not args.write:
        print("\n".join(lines))
        return 0
    for path in args.write:
        changed = write_headline(path, lines)
        print(f"{path}: {'table written' if changed else 'table already current'}")
    return 0
