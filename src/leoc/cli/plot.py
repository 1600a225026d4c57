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
    plot.add_argument(
        "--compare",
        type=Path,
        metavar="OTHER_DIR",
        help="a reproduce folder of the other implementation variant: the report's appendix-D "
        "table then sets both beside the paper (recorded in RUN_DIR's meta.json, so later "
        "'leoc plot RUN_DIR' keeps it)",
    )
    plot.add_argument(
        "--refresh-lqr-reference",
        action="store_true",
        help="first remake the LQR reference of every run's proved region written before it "
        "kept the LQR's best V (the LQR is proved, seconds per run; the trained controllers' "
        "proofs are kept) and rewrite those evaluation.json files atomically",
    )
    plot.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from leoc.experiments.report import record_companion, write_report

    if args.refresh_lqr_reference:
        from leoc.experiments.evaluators import refresh_lqr_references

        count = refresh_lqr_references(args.run_dir)
        print(f"{count} run(s) given the LQR's best-V reference")
    if args.compare is not None:
        record_companion(args.run_dir, args.compare)
    path = write_report(args.run_dir)
    print(f"figures and report regenerated: {path}")
    return 0
