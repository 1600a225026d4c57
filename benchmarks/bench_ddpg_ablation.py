"""The DDPG ablation (issue 20): success rate against budget, per system, controller and setting.

Runs the grid of :mod:`leoc.experiments.ablation` (leoc's defaults, the authors' full DDPG
setup, and leoc's defaults with one authors' choice switched on at a time; the DDPG baseline,
paper-relevance hybrid and ROA hybrid; cart-pole, mountain car and the pendulum as the control;
5 seeds for leoc and authors, 3 per single-factor setting) through the sweep backend: local
worker processes or a Ray cluster, resumable (a rerun skips every run whose ``result.json``
exists; each is written atomically), with progress lines and an ETA. A published folder
(``--publish``: records, logs and the pinned plan, no models) resumes too: copy it into
``--out`` on another machine and rerun the same command; only the missing runs train.

Success at budget T: the controller the run would deliver at T (the actor at step T, or the
best of the last third of T for the settings that select) holds the operating point in every
held-out swing-up episode; see :mod:`leoc.experiments.ablation`. At the end the tables are
written into ``--out`` (``ablation.md``, ``success_vs_budget.csv``, ``ablation.json``,
``success_vs_budget.png``) and printed; ``--publish DEST`` also copies the records (not the
models) to DEST and writes them there.

Usage::

    python benchmarks/bench_ddpg_ablation.py [--systems cartpole ...] [--settings leoc ...]
        [--controllers ddpg_baseline ...] [--seeds 0 1 2] [--budget 15000 | cartpole=30000]
        [--eval-interval 300 | cartpole=300] [--test-episodes 5] [--overrides JSON]
        [--jobs 2] [--backend local|ray] [--address ADDR] [--out DIR]
        [--publish DEST] [--publish-only] [--table-every 2000] [--dry-run]

The full grid (216 runs, hours)::

    nice -n 15 python benchmarks/bench_ddpg_ablation.py --out runs/ddpg-ablation --jobs 2 \\
        --publish results/ddpg-ablation

SAC's success rate over 5 seeds on the three systems at leoc's budgets, with the same
held-out test (``results/sac-defaults``; SAC takes the settings ``defaults``, ``leoc``,
``exit_penalty`` and its own ``SAC_TUNING_SETTINGS``)::

    nice -n 15 python benchmarks/bench_ddpg_ablation.py --out runs/sac-defaults --jobs 2 \\
        --controllers sac_hybrid_roa sac_hybrid sac_baseline --settings defaults \\
        --seeds 0 1 2 3 4 --budget cartpole=21000 mountaincar=20000 pendulum=10000 \\
        --publish results/sac-defaults
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from collections.abc import Sequence

from leoc.experiments.ablation import (
    ABLATION_CONTROLLERS,
    ABLATION_SYSTEMS,
    ALL_SETTINGS,
    GRID_CONTROLLERS,
    SAC_COST_FACTOR,
    SETTINGS,
    TEST_EPISODES,
    AblationPlan,
    expected_seconds,
    grid_specs,
    run_ablation,
)
from leoc.experiments.ablation_report import DEFAULT_TABLE_EVERY, publish_ablation
from leoc.experiments.sweep import BACKENDS, format_seconds

DEFAULT_OUT = "runs/ddpg-ablation"


def per_system(values: Sequence[str] | None, systems: Sequence[str], name: str) -> dict[str, int]:
    """``["20000"]`` (every system) or ``["cartpole=30000", ...]`` as ``{system: int}``."""
    found: dict[str, int] = {}
    for value in values or ():
        system, sep, number = value.rpartition("=")
        targets = [system] if sep else list(systems)
        if sep and system not in systems:
            raise SystemExit(f"--{name}: {system!r} is not among --systems {list(systems)}")
        try:
            count = int(number)
        except ValueError:
            raise SystemExit(f"--{name}: expected INT or SYSTEM=INT, found {value!r}") from None
        found.update(dict.fromkeys(targets, count))
    return found


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        description=__doc__.splitlines()[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--systems", nargs="+", default=list(ABLATION_SYSTEMS))
    parser.add_argument("--settings", nargs="+", default=list(SETTINGS), choices=ALL_SETTINGS)
    parser.add_argument(
        "--controllers", nargs="+", default=list(ABLATION_CONTROLLERS), choices=GRID_CONTROLLERS
    )
    parser.add_argument(
        "--seeds",
        type=int,
        nargs="+",
        help="seeds of every setting (default: 5 for leoc and "
        "authors, 3 for the single-factor settings)",
    )
    parser.add_argument(
        "--budget",
        nargs="+",
        help="environment steps: INT or SYSTEM=INT (default: the paper's, 10k / 15k / 10k)",
    )
    parser.add_argument(
        "--eval-interval",
        nargs="+",
        help="steps between evaluations: INT or SYSTEM=INT "
        "(default: the authors', 200 / 300 / 200)",
    )
    parser.add_argument("--test-episodes", type=int, default=TEST_EPISODES)
    parser.add_argument(
        "--overrides",
        default="{}",
        help="JSON object of DDPGConfig fields set in every cell "
        "(e.g. small networks for a smoke run)",
    )
    parser.add_argument("--jobs", type=int, default=None)
    parser.add_argument("--backend", choices=BACKENDS, default="local")
    parser.add_argument("--address", default=None, help="Ray cluster (with --backend ray)")
    parser.add_argument("--out", default=DEFAULT_OUT)
    parser.add_argument("--publish", default=None, metavar="DEST")
    parser.add_argument("--publish-only", action="store_true", help="no runs: tables only")
    parser.add_argument("--table-every", type=int, default=DEFAULT_TABLE_EVERY)
    parser.add_argument("--dry-run", action="store_true", help="list the runs and their cost")
    return parser.parse_args(argv)


def make_plan(args: argparse.Namespace) -> AblationPlan:
    try:
        overrides = json.loads(args.overrides)
    except json.JSONDecodeError as error:
        raise SystemExit(f"--overrides: expected a JSON object ({error})") from None
    if not isinstance(overrides, dict):
        raise SystemExit(f"--overrides: expected a JSON object, found {args.overrides!r}")
    try:
        return AblationPlan(
            budgets=per_system(args.budget, args.systems, "budget"),
            eval_intervals=per_system(args.eval_interval, args.systems, "eval-interval"),
            test_episodes=args.test_episodes,
            overrides=overrides,
        )
    except ValueError as error:
        raise SystemExit(str(error)) from None


def main(argv: Sequence[str] | None = None) -> None:
    args = parse_args(argv)
    if not args.publish_only:
        plan = make_plan(args)
        try:
            specs = grid_specs(args.systems, args.controllers, args.settings, args.seeds)
        except ValueError as error:
            raise SystemExit(str(error)) from None
        cost = expected_seconds(plan)
        total = sum(cost(spec) for spec in specs)
        workers = args.jobs or 2
        print(
            f"{len(specs)} runs ({', '.join(args.systems)}; {', '.join(args.settings)}); "
            f"budgets {[plan.budget_for(s) for s in args.systems]} steps; expected compute "
            f"{format_seconds(total)} of one worker, about {format_seconds(total / workers)} on "
            f"{workers} (results/paper's measured DDPG costs; SAC x{SAC_COST_FACTOR}); "
            f"out {args.out}",
            flush=True,
        )
        if args.dry_run:
            for spec in specs:
                print(f"  {spec.key}  ~{cost(spec):.0f} s")
            return
        try:
            result = run_ablation(
                args.out,
                specs,
                plan,
                backend=args.backend,
                jobs=args.jobs,
                address=args.address,
                command=shlex.join([sys.executable, *sys.argv]),
            )
        except KeyboardInterrupt:
            print(f"interrupted; rerun the same command to continue ({args.out})", flush=True)
            raise SystemExit(130) from None
        except ValueError as error:
            raise SystemExit(str(error)) from None
        if result.failed:
            print(f"{len(result.failed)} run(s) failed: {', '.join(sorted(result.failed))}")
    markdown = publish_ablation(args.out, None, args.table_every)
    print(markdown.read_text())
    print(f"tables and figure: {markdown.parent}")
    if args.publish:
        published = publish_ablation(args.out, args.publish, args.table_every)
        print(f"published: {published.parent}")


if __name__ == "__main__":
    from leoc.cli import quiet_on_broken_pipe

    raise SystemExit(quiet_on_broken_pipe(main))
