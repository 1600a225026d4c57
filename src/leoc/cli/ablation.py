"""``leoc ablation``: the DDPG/SAC ablation study, success rate against budget per setting.

Runs a grid of :mod:`leoc.experiments.ablation` (systems x controllers x settings x seeds) through
the sweep backend, then writes its tables and figure (:mod:`leoc.experiments.ablation_report`)
and prints the tables. Finished runs are kept: rerunning the same command resumes.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from collections.abc import Sequence
from typing import Any

from leoc.cli._args import SYSTEM_HELP, non_negative_int, positive_int, system_name
from leoc.cli.reproduce import add_sweep_arguments
from leoc.cli.train import DEFAULT_RUNS_DIR
from leoc.names import (
    ABLATION_ALL_SETTINGS,
    ABLATION_CONTROLLERS,
    ABLATION_SAC_CONTROLLERS,
    ABLATION_SETTINGS,
    ABLATION_SYSTEM_NAMES,
    ABLATION_TD3_CONTROLLERS,
    ABLATION_TEST_EPISODES,
)

DEFAULT_OUT = DEFAULT_RUNS_DIR / "ddpg-ablation"
#: The library's parameter names in its error messages, and the options that set them.
OPTION_OF = {
    "budgets": "--budget",
    "eval_intervals": "--eval-interval",
    "test_episodes": "--test-episodes",
    "overrides": "--overrides",
    "out": "--out",
    "jobs": "--jobs",
    "address": "--address",
    "backend": "--backend",
}


def add_parser(commands: Any) -> None:
    """Add the ``ablation`` command to the subparsers ``commands``."""
    ablation = commands.add_parser(
        "ablation",
        help="the DDPG/SAC ablation study: success rate against budget per setting",
        description="Train the grid of the DDPG ablation (systems x controllers x settings x "
        "seeds; a setting is leoc's defaults with some of the authors' DDPG choices switched "
        "on, or one of SAC's), test each run's delivered controller on held-out swing-ups at "
        "every evaluated budget, and write ablation.md, success_vs_budget.csv/.png and "
        "ablation.json into --out. Finished runs are kept: rerunning the same command resumes "
        "(a published folder too, copied into --out).",
    )
    _add_grid_arguments(ablation)
    _add_plan_arguments(ablation)
    add_sweep_arguments(ablation)
    ablation.add_argument(
        "--out", default=str(DEFAULT_OUT), help=f"study folder (default {DEFAULT_OUT})"
    )
    ablation.add_argument(
        "--publish",
        metavar="DEST",
        help="also copy the records, logs and plan (not the models) to DEST and write the "
        "tables there",
    )
    ablation.add_argument(
        "--publish-only", action="store_true", help="train nothing: the tables of --out only"
    )
    ablation.add_argument(
        "--table-every",
        type=positive_int,
        metavar="STEPS",
        help="spacing of the budget columns of the markdown tables (default 1000 steps)",
    )
    ablation.add_argument(
        "--dry-run", action="store_true", help="list the runs and their expected cost, run none"
    )
    ablation.set_defaults(run=run)


def _add_grid_arguments(ablation: argparse.ArgumentParser) -> None:
    """The runs of the grid: ``--systems``, ``--controllers``, ``--settings``, ``--seeds``."""
    ablation.add_argument(
        "--systems",
        nargs="+",
        type=system_name,
        default=list(ABLATION_SYSTEM_NAMES),
        metavar="SYSTEM",
        help=f"systems (default: {' '.join(ABLATION_SYSTEM_NAMES)}); {SYSTEM_HELP}",
    )
    ablation.add_argument(
        "--controllers",
        nargs="+",
        choices=ABLATION_CONTROLLERS + ABLATION_SAC_CONTROLLERS + ABLATION_TD3_CONTROLLERS,
        default=list(ABLATION_CONTROLLERS),
        metavar="CONTROLLER",
        help=f"controllers (default: {' '.join(ABLATION_CONTROLLERS)}; also "
        f"{', '.join(ABLATION_SAC_CONTROLLERS + ABLATION_TD3_CONTROLLERS)})",
    )
    ablation.add_argument(
        "--settings",
        nargs="+",
        choices=ABLATION_ALL_SETTINGS,
        default=list(ABLATION_SETTINGS),
        metavar="SETTING",
        help=f"settings (default: {' '.join(ABLATION_SETTINGS)}; also "
        f"{', '.join(ABLATION_ALL_SETTINGS[len(ABLATION_SETTINGS) :])}); a setting that "
        "changes nothing on a system or does not exist for a controller is left out there",
    )
    ablation.add_argument(
        "--seeds",
        nargs="+",
        type=non_negative_int,
        metavar="SEED",
        help="seeds of every setting (default: 0-4 for leoc, authors and defaults, 0-2 for "
        "the others)",
    )


def _add_plan_arguments(ablation: argparse.ArgumentParser) -> None:
    """What every run of the folder shares: budgets, evaluations, held-out test, overrides."""
    ablation.add_argument(
        "--budget",
        nargs="+",
        metavar="INT|SYSTEM=INT",
        help="environment steps of each run, for every system or per system (default: the "
        "paper's budget of each system; the first line of the output says them); a multiple "
        "of the evaluation interval",
    )
    ablation.add_argument(
        "--eval-interval",
        nargs="+",
        metavar="INT|SYSTEM=INT",
        help="environment steps between evaluations, for every system or per system (default: "
        "the authors' interval of each system)",
    )
    ablation.add_argument(
        "--test-episodes",
        type=positive_int,
        default=ABLATION_TEST_EPISODES,
        help=f"held-out swing-up episodes of each evaluation (default {ABLATION_TEST_EPISODES})",
    )
    ablation.add_argument(
        "--overrides",
        default="{}",
        metavar="JSON",
        help="DDPGConfig fields set in every run, as a JSON object (e.g. small networks for a "
        'quick check: \'{"actor_hidden": [16, 16], "critic_hidden": [16, 16]}\')',
    )


def per_system(values: Sequence[str] | None, systems: Sequence[str], option: str) -> dict[str, int]:
    """``["20000"]`` (every system of ``systems``) or ``["cartpole=30000", ...]`` as
    ``{system: int}``; raises ValueError naming ``option`` on anything else."""
    found: dict[str, int] = {}
    for value in values or ():
        system, sep, number = value.rpartition("=")
        if sep and system not in systems:
            raise ValueError(f"{option}: {system!r} is not among --systems {list(systems)}")
        try:
            count = int(number)
        except ValueError:
            count = 0
        if count < 1:
            raise ValueError(f"{option}: expected INT or SYSTEM=INT, INT >= 1, found {value!r}")
        found.update(dict.fromkeys([system] if sep else systems, count))
    return found


def make_plan(args: argparse.Namespace) -> Any:
    """The :class:`~leoc.experiments.ablation.AblationPlan` of the parsed arguments."""
    from leoc.experiments.ablation import AblationPlan

    try:
        overrides = json.loads(args.overrides)
    except json.JSONDecodeError as error:
        raise ValueError(f"--overrides: expected a JSON object ({error})") from None
    if not isinstance(overrides, dict):
        raise ValueError(f"--overrides: expected a JSON object, found {args.overrides!r}")
    return AblationPlan(
        budgets=per_system(args.budget, args.systems, "--budget"),
        eval_intervals=per_system(args.eval_interval, args.systems, "--eval-interval"),
        test_episodes=args.test_episodes,
        overrides=overrides,
    )


def run(args: argparse.Namespace) -> int:
    try:
        if not args.publish_only:
            _train(args)
            if args.dry_run:
                return 0
        _publish(args)
    except ValueError as error:
        raise ValueError(_named_option(str(error))) from None
    return 0


def _named_option(message: str) -> str:
    """``message`` with a leading library parameter name (``budgets: ...``) replaced by the
    option that sets it (``--budget: ...``)."""
    name, sep, rest = message.partition(":")
    return f"{OPTION_OF[name]}:{rest}" if sep and name in OPTION_OF else message


def _train(args: argparse.Namespace) -> None:
    """Print the grid and its expected cost, then run what is not done yet (none: --dry-run)."""
    from leoc.experiments.ablation import (
        SAC_COST_FACTOR,
        expected_seconds,
        grid_specs,
        run_ablation,
    )
    from leoc.experiments.sweep import format_seconds

    plan = make_plan(args)
    specs = grid_specs(args.systems, args.controllers, args.settings, args.seeds)
    cost = expected_seconds(plan)
    total = sum(cost(spec) for spec in specs)
    budgets = {system: plan.budget_for(system) for system in args.systems}
    intervals = {system: plan.eval_interval_for(system) for system in args.systems}
    print(
        f"{len(specs)} runs ({', '.join(args.systems)}; {', '.join(args.settings)}); budgets "
        f"{budgets} steps, evaluated every {intervals}; expected compute "
        f"{format_seconds(total)} on one worker (results/paper's measured DDPG costs; SAC "
        f"x{SAC_COST_FACTOR}); out {args.out}",
        flush=True,
    )
    if args.dry_run:
        for spec in specs:
            print(f"  {spec.key}  ~{cost(spec):.0f} s")
        return
    result = run_ablation(
        args.out,
        specs,
        plan,
        backend=args.backend,
        jobs=args.jobs,
        address=args.address,
        command=shlex.join(sys.argv),
    )
    if result.failed:
        print(f"{len(result.failed)} run(s) failed: {', '.join(sorted(result.failed))}")


def _publish(args: argparse.Namespace) -> None:
    """Write the tables and figure into --out (and --publish), print the tables."""
    from leoc.experiments.ablation_report import DEFAULT_TABLE_EVERY, publish_ablation

    every = args.table_every or DEFAULT_TABLE_EVERY
    markdown = publish_ablation(args.out, None, every)
    print(markdown.read_text())
    print(f"tables and figure: {markdown.parent}")
    if args.publish:
        published = publish_ablation(args.out, args.publish, every)
        print(f"published: {published.parent}")
