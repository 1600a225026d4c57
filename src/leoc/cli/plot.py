"""``leoc plot``: regenerate the figures and report of a reproduce folder."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any


def add_parser(commands: Any) -> None:
    """Add the ``plot`` command to the subparsers ``commands``."""
    plot = commands.add_parser(
        "plot",
        help="regenerate the figures and report of a reproduce folder from saved numbers",
        description="Rebuild results.json, the CSV files, every figure and report.md of a "
        "folder written by 'leoc reproduce' (or 'leoc publish') from its meta.json and the "
        "runs' evaluation.json files; nothing is trained or simulated.",
    )
    plot.add_argument(
        "run_dir", type=Path, metavar="RUN_DIR", help="the reproduce or published folder"
    )
    plot.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from leoc.experiments.report import write_report

    path = write_report(args.run_dir)
    print(f"figures and report regenerated: {path}")
    return 0
