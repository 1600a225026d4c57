"""``leoc reproduce``: train and evaluate every controller of the paper, write the report."""

from __future__ import annotations

import argparse
from typing import Any

from leoc.cli._args import positive_int, system_name
from leoc.cli.train import DEFAULT_RUNS_DIR
from leoc.names import (
    BACKEND_NAMES,
    CONTROLLERS,
    DEFAULT_CONTROLLERS,
    PAPER_SYSTEM_NAMES,
    PROFILE_NAMES,
    VARIANT_NAMES,
)


def add_parser(commands: Any) -> None:
    """Add the ``reproduce`` command to the subparsers ``commands``."""
    reproduce = commands.add_parser(
        "reproduce",
        help="train and evaluate every controller of the paper and write the report",
        description="Train (or design) the linear references and the DDPG, SAC and PILCO "
        "baselines and hybrids on the three systems over seeds, in parallel workers, then "
        "evaluate responses, robustness and relevance and write report.md with CSV/JSON/PNG. "
        "Finished "
        "runs are kept: rerunning the same command resumes.",
    )
    reproduce.add_argument(
        "--profile",
        choices=PROFILE_NAMES,
        default="quick",
        help="quick (default: 1 seed, reduced budgets), paper (the paper's PILCO budgets, "
        "leoc's DDPG/SAC budgets, 5 seeds) or smoke (a tiny pipeline check)",
    )
    reproduce.add_argument(
        "--out",
        help="output folder (default runs/reproduce-PROFILE, runs/reproduce-PROFILE-authors for "
        "the authors' variant)",
    )
    reproduce.add_argument(
        "--variant",
        choices=VARIANT_NAMES,
        default="leoc",
        help="implementation: leoc's defaults, or the authors' (nrjc/LEOC: their LQR scaled by "
        "u_max with a sin squash, their env rules, DDPG and PILCO settings); default leoc",
    )
    add_sweep_arguments(reproduce)
    reproduce.add_argument(
        "--seeds", type=positive_int, help="number of seeds (default per profile)"
    )
    reproduce.add_argument(
        "--systems",
        nargs="+",
        type=system_name,
        default=list(PAPER_SYSTEM_NAMES),
        metavar="SYSTEM",
        help=f"systems to run (default: {' '.join(PAPER_SYSTEM_NAMES)})",
    )
    reproduce.add_argument(
        "--controllers",
        nargs="+",
        choices=CONTROLLERS,
        default=list(DEFAULT_CONTROLLERS),
        help="controllers to run (default: the two linear references and the paper's four; "
        "add ddpg_hybrid_roa / pilco_hybrid_roa for the ROA-relevance hybrids, "
        "ddpg_hybrid_lyapunov / td3_hybrid_lyapunov / sac_hybrid_lyapunov for the Lyapunov-"
        "relevance hybrids (PILCO has none), td3_baseline / td3_hybrid / td3_hybrid_roa for TD3 "
        "and sac_baseline / sac_hybrid / sac_hybrid_roa for SAC, at the DDPG budgets)",
    )
    reproduce.set_defaults(run=run)


def add_sweep_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--jobs``, ``--backend`` and ``--address`` (where a sweep's runs run) to
    ``parser``; ``leoc ablation`` takes them too."""
    parser.add_argument(
        "--jobs",
        type=positive_int,
        help="runs at a time (default: the CPU count; on Ray, as many as the cluster's CPUs)",
    )
    parser.add_argument(
        "--backend",
        choices=BACKEND_NAMES,
        default="local",
        help="local: worker processes on this machine (default); ray: one Ray task per run "
        "(needs pip install 'leoc[ray]')",
    )
    parser.add_argument(
        "--address",
        help="Ray only: the cluster to join ('auto' inside a cluster started with 'ray start', "
        "or HEAD_IP:6379); default: a private Ray instance on this machine",
    )


def run(args: argparse.Namespace) -> int:
    from leoc.experiments.reproduce import reproduce
    from leoc.experiments.summary import summary_lines

    suffix = "" if args.variant == "leoc" else f"-{args.variant}"
    out = args.out or str(DEFAULT_RUNS_DIR / f"reproduce-{args.profile}{suffix}")
    path = reproduce(
        out,
        profile_name=args.profile,
        jobs=args.jobs,
        seeds=args.seeds,
        systems=args.systems,
        controllers=args.controllers,
        backend=args.backend,
        address=args.address,
        variant=args.variant,
    )
    for line in summary_lines(path.parent):
        print(line)
    return 0
