"""``leoc train``: train a baseline or hybrid controller with PILCO, DDPG, TD3 or SAC."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from leoc.cli._args import SYSTEM_HELP, non_negative_int, positive_int, system_name
from leoc.names import (
    LEARNER_NAMES,
    PROFILE_NAMES,
    RELEVANCE_NAMES,
    VARIANT_NAMES,
    ControllerName,
)

ALGO_CHOICES = LEARNER_NAMES
MODEL_FREE_ALGOS = ("ddpg", "td3", "sac")  # leoc.sb3.config.ALGOS, without importing SB3
DEFAULT_RUNS_DIR = Path("runs")


DESCRIPTION = (
    "Train a baseline (the learned policy alone) or the LEOC hybrid (LQR near the operating "
    "point, the learned policy elsewhere) with PILCO, DDPG, TD3 or SAC (for SAC the hybrid is "
    "its deterministic action, the squashed mean; it explores with its own Gaussian around it). "
    "The run folder keeps the weights, config, learning curve and checkpoints. Rerunning the "
    "same command resumes an interrupted run from its last checkpoint (PILCO: every iteration; "
    "DDPG/TD3/SAC: every 1000 steps, exactly as if it had not stopped) and returns a finished "
    "one without training; PILCO extends a run given more --iterations. A run folder holding "
    "another configuration is refused unless --overwrite."
)


def add_parser(commands: Any) -> None:
    """Add the ``train`` command to the subparsers ``commands``."""
    train = commands.add_parser(
        "train", help="train a baseline or hybrid controller", description=DESCRIPTION
    )
    train.add_argument("system", type=system_name, metavar="SYSTEM", help=SYSTEM_HELP)
    train.add_argument("--algo", choices=ALGO_CHOICES, required=True, help="learning algorithm")
    train.add_argument("--hybrid", action="store_true", help="train the LEOC hybrid")
    train.add_argument(
        "--relevance",
        choices=RELEVANCE_NAMES,
        help="the hybrid's relevance: 'paper', r(x) = (1 + d)^-2 (default), or 'roa', exactly 1 "
        "on the LQR's proved region of attraction; only with --hybrid",
    )
    train.add_argument(
        "--variant",
        choices=VARIANT_NAMES,
        default="leoc",
        help="implementation: leoc's defaults, or the authors' (nrjc/LEOC: their LQR and sin "
        "squash, their step rules, DDPG and PILCO settings and budgets); default leoc",
    )
    train.add_argument(
        "--profile",
        choices=PROFILE_NAMES,
        help="budgets and settings of a 'leoc reproduce' profile (quick: reduced budgets; "
        "smoke: a tiny pipeline check whose controller is not trained); default: the learner's "
        "own (the variant's budgets); --steps/--iterations override its budget",
    )
    train.add_argument("--seed", type=non_negative_int, default=0, help="seed (default 0)")
    train.add_argument(
        "--out",
        type=Path,
        help="run folder (default runs/SYSTEM/CONTROLLER/seedN, under runs/authors/ for the "
        "authors' variant; CONTROLLER e.g. td3_hybrid_roa)",
    )
    train.add_argument(
        "--iterations", type=positive_int, help="PILCO iterations (default per system)"
    )
    train.add_argument(
        "--steps",
        type=positive_int,
        help="DDPG/TD3/SAC environment steps (default per system: 10k for the pendulum, 21k for "
        "the cart-pole, 20k for the mountain car)",
    )
    train.add_argument(
        "--overwrite",
        action="store_true",
        help="train afresh in the run folder even if it holds a run of another configuration "
        "(default: refuse, naming the settings that differ)",
    )
    train.add_argument("--quiet", action="store_true", help="no progress output")
    train.set_defaults(run=run)


def check_budget_arguments(args: argparse.Namespace) -> None:
    """``--iterations`` is PILCO's budget and ``--steps`` the model-free learners'; giving one
    to the other kind of learner is an error (ValueError naming the argument), not a silent
    default."""
    if args.algo == "pilco" and args.steps is not None:
        raise ValueError(
            f"--steps: only for --algo {'/'.join(MODEL_FREE_ALGOS)}; PILCO's budget is --iterations"
        )
    if args.algo in MODEL_FREE_ALGOS and args.iterations is not None:
        raise ValueError(
            f"--iterations: only for --algo pilco; the budget of --algo {args.algo} is --steps"
        )


def default_run_dir(args: argparse.Namespace) -> Path:
    """``runs[/VARIANT]/SYSTEM/CONTROLLER/seedN`` (``leoc.training.run_folder``'s scheme, with
    the variant's folder for any but leoc's): CONTROLLER names the learner and the kind as
    ``leoc reproduce``'s controllers do (``td3_hybrid_roa``)."""
    relevance = (args.relevance or "paper") if args.hybrid else None
    controller = ControllerName(args.algo, relevance).name
    root = DEFAULT_RUNS_DIR if args.variant == "leoc" else DEFAULT_RUNS_DIR / args.variant
    return root / args.system / controller / f"seed{args.seed}"


def controller_of(args: argparse.Namespace) -> Any:
    """The :class:`~leoc.learners.ControllerSpec` ``args`` describe (``--algo``, ``--hybrid``,
    ``--relevance``)."""
    from leoc.learners import ControllerSpec

    relevance = (args.relevance or "paper") if args.hybrid else None
    return ControllerSpec.from_name(ControllerName(args.algo, relevance).name)


def run_settings(args: argparse.Namespace) -> dict[str, Any]:
    """Config fields of the run ``args`` describe: the variant's settings at the profile's (or
    the given) budget and the profile's overrides
    (:meth:`leoc.experiments.profiles.Profile.training_settings`, as ``leoc reproduce``)."""
    from leoc.experiments.profiles import Profile, get_profile
    from leoc.experiments.variants import get_variant

    profile = get_profile(args.profile) if args.profile else Profile("default", (), {}, {})
    budget = args.iterations if args.algo == "pilco" else args.steps
    variant = get_variant(args.variant)
    return profile.training_settings(variant, controller_of(args), args.system, budget)


def run(args: argparse.Namespace) -> int:
    """Train the controller ``args`` describe with its learner (``leoc.learners``); prints the
    run folder."""
    from leoc.experiments.variants import get_variant
    from leoc.learners import get_learner

    check_budget_arguments(args)
    if args.relevance is not None and not args.hybrid:
        raise ValueError(
            f"--relevance: only with --hybrid (a baseline has no relevance), found --relevance "
            f"{args.relevance} without it"
        )
    run_dir = args.out or default_run_dir(args)
    settings = run_settings(args)
    controller = controller_of(args)
    # the system, built once: the variant's, stepping under the rules the settings record
    system = get_variant(args.variant).system(args.system)
    result = get_learner(args.algo).train(
        system,
        controller,
        args.seed,
        run_dir,
        settings,
        progress=not args.quiet,
        overwrite=args.overwrite,
    )
    print(f"run folder: {result.run_dir}")
    return 0
