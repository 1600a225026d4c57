"""``leoc gym-study``: LEOC on MuJoCo's inverted pendulums at growing start noise.

Trains and evaluates the study of :mod:`leoc.experiments.gym_study` (envs x start noises x
controllers x seeds) into ``--out``, and writes ``study.json``, ``README.md`` and one figure per
env there. Finished runs are kept: rerunning the same command resumes.
"""

from __future__ import annotations

import argparse
import shlex
from typing import Any

from leoc.cli._args import non_negative_int, positive_int
from leoc.names import (
    GYM_STUDY_DEFAULT_NOISE,
    GYM_STUDY_ENVS,
    GYM_STUDY_NOISES,
    GYM_STUDY_PROFILES,
)

#: The library's parameter names in its error messages, and the options that set them.
OPTION_OF = {
    "noises": "--noises",
    "envs": "--envs",
    "env": "--envs",
    "seeds": "--seeds",
    "steps": "--steps",
    "seed": "--seed",
    "profile": "--profile",
    "episodes": "--episodes",
}


def noise_name(text: str) -> str:
    """argparse type of ``--noises``: ``default`` or a positive number (kept as written)."""
    if text == GYM_STUDY_DEFAULT_NOISE:
        return text
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not 0.0 < value < float("inf"):
        raise argparse.ArgumentTypeError(
            f"expected {GYM_STUDY_DEFAULT_NOISE!r} or a positive reset_noise_scale, found {text!r}"
        )
    return text


def add_parser(commands: Any) -> None:
    """Add the ``gym-study`` command to the subparsers ``commands``."""
    study = commands.add_parser(
        "gym-study",
        help="LEOC on MuJoCo's inverted pendulums at growing start noise (gymnasium)",
        description="For each env, start noise (reset_noise_scale), controller (the clipped LQR "
        "alone, SAC alone with rl-baselines3-zoo's MuJoCo settings, the SAC hybrid with the "
        "paper's relevance, the SAC hybrid with the ROA relevance where the observation is the "
        "state) and seed: train into --out/runs/ENV/NOISE/CONTROLLER/seedK, evaluate on the same "
        "seeded starts (skipping starts that end at the first step whatever the action), "
        "and write study.json, README.md and a learning-curve figure per env. "
        "Rerunning the same command resumes; finished runs are not retrained.",
    )
    study.add_argument("--out", required=True, help="study folder")
    study.add_argument(
        "--profile",
        choices=GYM_STUDY_PROFILES,
        default="full",
        help="smoke: tiny networks, 300 steps, one seed (a pipeline check); full: the zoo's "
        "settings, 30k steps per run, 5 seeds, 30 evaluation episodes (default)",
    )
    study.add_argument("--seeds", type=positive_int, help="number of seeds (default: profile's)")
    study.add_argument(
        "--seed", type=non_negative_int, default=0, help="seed base: seeds SEED, SEED+1, ..."
    )
    study.add_argument(
        "--steps", type=positive_int, help="environment steps per SAC run (default: profile's)"
    )
    study.add_argument(
        "--episodes",
        type=positive_int,
        help="evaluation episodes per run (default: profile's)",
    )
    study.add_argument(
        "--envs",
        nargs="+",
        default=list(GYM_STUDY_ENVS),
        metavar="ENV_ID",
        help=f"gymnasium ids (default: {' '.join(GYM_STUDY_ENVS)})",
    )
    study.add_argument(
        "--noises",
        nargs="+",
        type=noise_name,
        default=list(GYM_STUDY_NOISES),
        metavar="NOISE",
        help=f"start noises: {GYM_STUDY_DEFAULT_NOISE!r} (the env's own) or a reset_noise_scale "
        f"(default: {' '.join(GYM_STUDY_NOISES)})",
    )
    study.add_argument(
        "--report-only",
        action="store_true",
        help="train nothing: write README.md and the figures from --out/study.json",
    )
    study.set_defaults(run=run)


def command_of(args: argparse.Namespace) -> str:
    """The ``leoc gym-study`` command line of ``args``, every option written out (the
    profile's defaults as the profile's name), so that it remakes the same study."""
    words = ["leoc", "gym-study", "--out", str(args.out), "--profile", args.profile]
    for flag in ("seeds", "seed", "steps", "episodes"):
        if getattr(args, flag) is not None:
            words += [f"--{flag}", str(getattr(args, flag))]
    words += ["--envs", *args.envs, "--noises", *args.noises]
    return shlex.join(words)


def run(args: argparse.Namespace) -> int:
    """Run (or resume) the study, or only write its report; prints the README's path."""
    try:
        if args.report_only:
            from leoc.experiments.gym_study_report import write_study_report

            readme = write_study_report(args.out)
        else:
            from leoc.experiments.gym_study import run_gym_study

            options = {"seeds": args.seeds, "seed": args.seed, "steps": args.steps}
            options["episodes"] = args.episodes
            run_gym_study(
                args.out,
                args.profile,
                envs=args.envs,
                noises=args.noises,
                command=command_of(args),
                **options,
            )
            readme = f"{args.out}/README.md"
    except ValueError as error:
        name, sep, rest = str(error).partition(":")
        raise ValueError(
            f"{OPTION_OF[name]}:{rest}" if sep and name in OPTION_OF else error
        ) from None
    print(f"report: {readme}")
    return 0
