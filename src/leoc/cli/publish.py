"""``leoc publish``: copy a reproduce or gym-study folder's numbers (not its weights) and write
the report."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any


def add_parser(commands: Any) -> None:
    """Add the ``publish`` command to the subparsers ``commands``."""
    publish = commands.add_parser(
        "publish",
        help="copy a reproduce folder's numbers (not its weights) to DEST and write the report "
        "there (for results kept in a repository)",
        description="Copy meta.json and every run's evaluation.json and train.log from RUN_DIR "
        "to DEST (no weights, checkpoints or trainer folders), then write the report, CSV files "
        "and figures in DEST; 'leoc plot DEST' regenerates them byte for byte. A gym-study "
        "folder: every run's evaluation.json, config.json and design.json, and study.json with "
        "its README where the study has one ('leoc gym-study --out DEST --report-only' "
        "regenerates it); a study still running is carried as its finished runs.",
    )
    publish.add_argument(
        "run_dir", type=Path, metavar="RUN_DIR", help="a reproduce or gym-study folder"
    )
    publish.add_argument("dest", type=Path, metavar="DEST", help="a folder outside RUN_DIR")
    publish.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from leoc.experiments.publish import publish

    path = publish(args.run_dir, args.dest)
    if path.is_dir():
        print(f"numbers copied (a study still running: no report yet): {path}")
    else:
        print(f"numbers copied and report written: {path}")
    return 0
