"""``leoc train``: train a baseline or hybrid controller with PILCO, DDPG, TD3 or SAC."""

from __future__ import annotations

import argparse
import re
from pathlib import Path
from typing import Any

from leoc.cli._args import (
    SYSTEM_HELP,
    add_env_option,
    category_level,
    env_kwargs_of,
    non_negative_int,
    numbers,
    positive_int,
    relevance_name,
    system_name,
)
from leoc.names import (
    GYM_PREFIX,
    LEARNER_NAMES,
    PROFILE_NAMES,
    RELEVANCE_NAMES,
    ROBUSTNESS_CATEGORIES,
    SELECTION_PLANTS,
    VARIANT_NAMES,
    ControllerName,
    gym_env_id,
    gym_folder_name,
)

ALGO_CHOICES = LEARNER_NAMES
MODEL_FREE_ALGOS = ("ddpg", "td3", "sac")  # leoc.sb3.config.ALGOS, without importing SB3
DEFAULT_RUNS_DIR = Path("runs")
RELEVANCE_PARAMETRISATIONS = ("log_lambda", "precision")
"""``leoc.policies.relevance.RELEVANCE_PARAMETRISATIONS`` without importing torch (the tests
check that they agree)."""
HYBRID_FLAGS = {
    "relevance": "--relevance",
    "relevance_parametrisation": "--relevance-parametrisation",
    "lambda_init": "--lambda-init",
    "learn_lambda": "--freeze-lambda",
    "rho_in_fraction": "--rho-in-fraction",
    "width_init": "--width-init",
    "learn_width": "--freeze-width",
    "r_min": "--r-min",
    "relevance_lr_scale": "--relevance-lr-scale",
    "relevance_power": "--relevance-power",
}
"""Each :class:`~leoc.policies.HybridSpec` field and the ``leoc train`` flag that sets it (a
``--freeze-X`` flag sets ``learn_X`` to False); only with ``--hybrid``."""

RUN_FLAGS = {**HYBRID_FLAGS, "selection_plants": "--select-on"}
"""Each config field a ``leoc train`` flag sets and that flag (:data:`HYBRID_FLAGS` and the
model-free learners' ``--select-on``): a learner's refusal of the field is led by the flag."""


DESCRIPTION = (
    "Train a baseline (the learned policy alone) or the LEOC hybrid (LQR near the operating "
    "point, the learned policy elsewhere) with PILCO, DDPG, TD3 or SAC (for SAC the hybrid is "
    "its deterministic action, the squashed mean; it explores with its own Gaussian around it). "
    "The run folder keeps the weights, config, learning curve and checkpoints. Rerunning the "
    "same command resumes an interrupted run from its last checkpoint (PILCO: every iteration; "
    "DDPG/TD3/SAC: every 1000 steps, exactly as if it had not stopped) and returns a finished "
    "one without training; PILCO extends a run given more --iterations. A run folder holding "
    "another configuration is refused unless --overwrite. --perturb and --randomise train on a "
    "perturbed plant (the robustness protocol's categories; docs/user_guide/"
    "robustness_protocol.md); the evaluations stay on the nominal plant."
)
PERTURBATION_FLAGS = {"fixed": "--perturb", "randomised": "--randomise"}

"""Each :class:`~leoc.systems.TrainingPerturbations` field and the ``leoc train`` flag that
fills it."""


def add_parser(commands: Any) -> None:
    """Add the ``train`` command to the subparsers ``commands``."""
    train = commands.add_parser(
        "train", help="train a baseline or hybrid controller", description=DESCRIPTION
    )
    train.add_argument(
        "system",
        type=train_system,
        metavar="SYSTEM",
        help=f"{SYSTEM_HELP}; or {GYM_PREFIX}ENV_ID, a gymnasium env trained on itself (e.g. "
        f"{GYM_PREFIX}InvertedPendulum-v5; DDPG/TD3/SAC, leoc's variant, no profile)",
    )
    train.add_argument("--algo", choices=ALGO_CHOICES, required=True, help="learning algorithm")
    train.add_argument("--hybrid", action="store_true", help="train the LEOC hybrid")
    add_relevance_arguments(train)
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
    add_process_arguments(train)
    add_env_option(train, f"{GYM_PREFIX}ENV_ID only, saved in the run's config")
    add_perturbation_arguments(train)
    train.set_defaults(run=run)


def add_process_arguments(train: argparse.ArgumentParser) -> None:
    """Add ``--quiet`` and ``--threads`` (how the run's process behaves) to ``train``."""
    train.add_argument("--quiet", action="store_true", help="no progress output")
    train.add_argument(
        "--threads",
        type=positive_int,
        help="torch threads of this run (default: torch's own, one per core); give 1 to each "
        "of several runs started side by side, which otherwise contend for the cores (two "
        "SAC runs on 2 cores: 4 against 23 steps/s each). Not recorded: a run resumes at any "
        "count, and its numbers may differ in the last bits between counts",
    )


def train_system(text: str) -> str:
    """argparse type of ``leoc train``'s SYSTEM: a system name (:func:`system_name`) or
    ``gym:ENV_ID`` (the id is checked when the env is made)."""
    if text.startswith(GYM_PREFIX):
        try:
            gym_env_id(text)
        except ValueError as error:
            raise argparse.ArgumentTypeError(str(error)) from None
        return text
    return system_name(text)


def add_perturbation_arguments(train: argparse.ArgumentParser) -> None:
    """Add ``--perturb`` and ``--randomise`` (training under perturbation) to ``train``."""
    group = train.add_argument_group(
        "training under perturbation (categories and units of 'leoc robustness': "
        f"{', '.join(ROBUSTNESS_CATEGORIES)}; a parameter error as parameter_error.CONSTANT; "
        "each category once; evaluations stay on the nominal plant)"
    )
    group.add_argument(
        "--perturb",
        action="append",
        type=category_level,
        metavar="CATEGORY=LEVEL",
        help="train on the plant with this level of CATEGORY in every episode (signed for "
        "actuator_gain and parameter_error: gain - 1, factor - 1); repeatable",
    )
    group.add_argument(
        "--randomise",
        "--randomize",
        dest="randomise",
        action="append",
        type=category_level,
        metavar="CATEGORY=MAX",
        help="domain randomisation: each training episode draws the level of CATEGORY "
        "uniformly between none and MAX (-MAX to MAX for actuator_gain and parameter_error, "
        "whole steps for action_delay), from --seed; repeatable",
    )
    group.add_argument(
        "--select-on",
        choices=SELECTION_PLANTS,
        default=None,
        help="DDPG/TD3/SAC: the plants model selection judges on: the nominal evaluation "
        "episodes (default), or, with --randomise, the same starts on plants of the training "
        "distribution (one stratum of each range per episode, fixed for the run); the "
        "learning curve stays nominal",
    )


def add_relevance_arguments(train: argparse.ArgumentParser) -> None:
    """Add ``--relevance`` and the flags of its parameters (:data:`HYBRID_FLAGS`) to
    ``train``."""
    relevance = train.add_argument_group(
        "relevance (only with --hybrid; each flag sets the HybridSpec field of its name, "
        "checked by HybridSpec; default: the variant's setting, else HybridSpec's default)"
    )
    relevance.add_argument(
        "--relevance",
        type=relevance_name,
        metavar="{" + ",".join(RELEVANCE_NAMES) + "}",
        help="the relevance design: 'paper', r(x) = (1 + d^p)^-2 (default; see --r-min and "
        "--relevance-power), 'roa', exactly 1 on the "
        "LQR's proved region of attraction, 'lyapunov', the paper's form with the LQR's V as d, "
        "or another of leoc.policies.RELEVANCE_DESIGNS",
    )
    relevance.add_argument(
        "--lambda-init",
        type=numbers,
        metavar="FLOAT[,FLOAT...]",
        help="paper relevance: initial diagonal of Lambda (> 0), one number or one per "
        "observation entry; lyapunov relevance: its lambda, one number (default 1)",
    )
    relevance.add_argument(
        "--freeze-lambda",
        action="store_true",
        default=None,
        help="paper and lyapunov relevances: training keeps Lambda at --lambda-init "
        "(learn_lambda=False)",
    )
    relevance.add_argument(
        "--relevance-parametrisation",
        choices=RELEVANCE_PARAMETRISATIONS,
        help="paper relevance: Lambda held as log lambda, or as the precision S = Lambda^-1 "
        "(unconstrained, nrjc/LEOC's DDPG actor); PILCO: log_lambda only",
    )
    relevance.add_argument(
        "--r-min",
        type=floor_value,
        metavar="FLOAT|none",
        help="paper relevance: floor Lambda so that r is at least this on the LQR's proved "
        "region of attraction, in (0, 1), or 'none', no floor (the paper's); default 0.5 "
        "(log lambda)",
    )
    relevance.add_argument(
        "--relevance-lr-scale",
        type=float,
        metavar="FLOAT",
        help="the relevance's parameters train at the actor's learning rate times this (> 0, "
        "default 1); DDPG/TD3/SAC",
    )
    relevance.add_argument(
        "--relevance-power",
        type=float,
        metavar="FLOAT",
        help="paper relevance (log lambda): p >= 1 of r = (1 + d^p)^-2 (default 2: the learned "
        "part leaks into the LQR's neighbourhood at fourth order, not second; 1: the paper's)",
    )
    add_roa_relevance_arguments(relevance)


NO_FLOOR = "none"
"""``--r-min``'s word for no floor on Lambda (``r_min=None``, the paper's relevance)."""


def floor_value(text: str) -> float | str:
    """``--r-min``'s value: a number, or :data:`NO_FLOOR` (argparse reports a bad one)."""
    return NO_FLOOR if text.strip().lower() == NO_FLOOR else float(text)


def add_roa_relevance_arguments(relevance: Any) -> None:
    """Add the ROA relevance's flags to the argument group ``relevance``."""
    relevance.add_argument(
        "--rho-in-fraction",
        type=float,
        metavar="FLOAT",
        help="ROA relevance: the flat top's level as a fraction of the certified rho, in (0, 1] "
        "(default 1)",
    )
    relevance.add_argument(
        "--width-init",
        type=float,
        metavar="FLOAT",
        help="ROA relevance: initial width (> 0) of the band over which r falls to 0 (default 1)",
    )
    relevance.add_argument(
        "--freeze-width",
        action="store_true",
        default=None,
        help="ROA relevance: training keeps the band width at --width-init (learn_width=False)",
    )


def hybrid_changes(args: argparse.Namespace) -> dict[str, Any]:
    """The :class:`~leoc.policies.HybridSpec` fields the relevance flags given set (a flag left
    out sets nothing)."""
    changes = {}
    for field, flag in HYBRID_FLAGS.items():
        value = getattr(args, flag.lstrip("-").replace("-", "_"), None)
        if value is not None:
            changes[field] = not value if flag.startswith("--freeze-") else value
    if changes.get("r_min") == NO_FLOOR:
        changes["r_min"] = None
    return changes


def with_flag(message: str, changes: dict[str, Any]) -> str:
    """``message`` (a ``ValueError``'s, ``"FIELD: ..."`` or ``"FIELD must ..."``) led by the
    flag that set FIELD, when a flag did (``--r-min: r_min: expected ...``); ``changes``: the
    fields the flags set (:func:`flag_changes`)."""
    field = re.split(r"\W", message, maxsplit=1)[0]
    return f"{RUN_FLAGS[field]}: {message}" if field in changes else message


def flag_changes(args: argparse.Namespace) -> dict[str, Any]:
    """The config fields of :data:`RUN_FLAGS` the flags given set: :func:`hybrid_changes` and
    ``selection_plants`` (``--select-on``)."""
    changes = hybrid_changes(args)
    if getattr(args, "select_on", None) is not None:
        changes["selection_plants"] = args.select_on
    return changes


def hybrid_of(args: argparse.Namespace) -> Any:
    """The :class:`~leoc.policies.HybridSpec` of ``--hybrid`` and the relevance flags (None
    without ``--hybrid``).

    Raises
    ------
    ValueError
        A relevance flag without ``--hybrid``, or a value ``HybridSpec`` refuses, naming the
        flag.
    """
    changes = hybrid_changes(args)
    if not args.hybrid:
        if changes:
            flags = ", ".join(HYBRID_FLAGS[field] for field in changes)
            raise ValueError(
                f"{flags}: only with --hybrid (a baseline has no relevance); add --hybrid or "
                f"leave {flags} out"
            )
        return None
    from leoc.policies.spec import HybridSpec

    try:
        return HybridSpec(**changes)
    except ValueError as error:
        raise ValueError(with_flag(str(error), changes)) from None


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
    return root / gym_folder_name(args.system) / controller / f"seed{args.seed}"


def controller_of(args: argparse.Namespace) -> Any:
    """The :class:`~leoc.learners.ControllerSpec` ``args`` describe (``--algo``, ``--hybrid``,
    ``--relevance`` and its parameters' flags: :func:`hybrid_of`)."""
    from leoc.learners import ControllerSpec

    return ControllerSpec(args.algo, hybrid_of(args))


def run_settings(args: argparse.Namespace) -> dict[str, Any]:
    """Config fields of the run ``args`` describe: the variant's settings at the profile's (or
    the given) budget and the profile's overrides
    (:meth:`leoc.experiments.profiles.Profile.training_settings`, as ``leoc reproduce``)."""
    from leoc.experiments.profiles import Profile, get_profile
    from leoc.experiments.variants import get_variant

    profile = get_profile(args.profile) if args.profile else Profile("default", (), {}, {})
    budget = args.iterations if args.algo == "pilco" else args.steps
    variant = get_variant(args.variant)
    settings = profile.training_settings(variant, controller_of(args), args.system, budget)
    # the flags given win over the variant's and the profile's refinements of the hybrid
    settings.update({k: v for k, v in hybrid_changes(args).items() if k != "relevance"})
    perturbations = perturbations_of(args)
    if perturbations is not None:  # the flags replace a profile's training perturbations
        settings["training_perturbations"] = perturbations
    select_on = getattr(args, "select_on", None)
    if select_on is not None:
        check_select_on(args.algo)
        settings["selection_plants"] = select_on
    return settings


def check_select_on(algo: str) -> None:
    """Refuse ``--select-on`` for PILCO (no model selection); what the model-free learners'
    config refuses of it (``'training'`` without ``--randomise``) comes back from the learner,
    led by the flag (:func:`with_flag`)."""
    if algo not in MODEL_FREE_ALGOS:
        raise ValueError(
            f"--select-on: expected it only with --algo {', '.join(MODEL_FREE_ALGOS)} (they "
            f"select a model among their evaluations), found --algo {algo}"
        )


def perturbations_of(args: argparse.Namespace) -> dict[str, Any] | None:
    """The ``training_perturbations`` setting of ``--perturb`` and ``--randomise``
    (:meth:`leoc.systems.TrainingPerturbations.as_dict`), checked against the system; None
    when neither is given.

    Raises
    ------
    ValueError
        Naming the flag, the entry, what was expected and what was found.
    """
    if not args.perturb and not args.randomise:
        return None
    from leoc.systems import TrainingPerturbations, make_system

    try:
        spec = TrainingPerturbations(tuple(args.perturb or ()), tuple(args.randomise or ()))
        spec.check(make_system(args.system))
    except ValueError as error:
        field, _, rest = str(error).partition(": ")
        if field not in PERTURBATION_FLAGS:
            raise
        raise ValueError(f"{PERTURBATION_FLAGS[field]}: {rest}") from None
    return spec.as_dict()


def check_run_folder_hybrid(run_dir: Path, hybrid: Any, overwrite: bool) -> None:
    """Refuse, naming the fields that differ, a run folder whose saved run is of another hybrid
    (``hybrid``: the run's final :class:`~leoc.policies.HybridSpec` or None); the learner's own
    check would name the whole spec dicts. A folder without ``config.json``, or ``overwrite``:
    nothing to check."""
    import json

    from leoc.policies.spec import legacy_hybrid_config

    path = run_dir / "config.json"
    if overwrite or not path.is_file():
        return
    try:
        saved = legacy_hybrid_config(json.loads(path.read_text())).get("hybrid")
    except (ValueError, TypeError, AttributeError):
        return  # not a learner's config: the learner's own check speaks
    here = None if hybrid is None else hybrid.to_dict()
    if saved == here:
        return
    if saved is None or here is None:
        kinds = ("a baseline", "a hybrid") if saved is None else ("a hybrid", "a baseline")
        shown = f"{kinds[0]} there, {kinds[1]} here"
    else:
        shown = "; ".join(
            f"{HYBRID_FLAGS.get(k, k)} ({k}): {saved.get(k)!r} there, {here.get(k)!r} here"
            for k in sorted(set(saved) | set(here))
            if saved.get(k) != here.get(k)
        )
    raise ValueError(
        f"run folder: {str(run_dir)!r} holds a run of another hybrid ({shown}); pass "
        "--overwrite to replace it, or choose another folder (--out)"
    )


def run(args: argparse.Namespace) -> int:
    """Train the controller ``args`` describe with its learner (``leoc.learners``); prints the
    run folder."""
    from leoc.experiments.variants import get_variant
    from leoc.learners import get_learner
    from leoc.policies.spec import with_hybrid_overrides

    set_threads(getattr(args, "threads", None))
    if gym_env_id(args.system) is not None:
        return run_gym(args)
    if getattr(args, "env_option", None):
        options = [f"{key}={value}" for key, value in args.env_option]
        raise ValueError(
            f"--env-option: expected only for a gymnasium env ({GYM_PREFIX}ENV_ID), found "
            f"{options} for the leoc system {args.system!r}"
        )
    check_budget_arguments(args)
    controller = controller_of(args)  # checks the relevance flags first
    run_dir = args.out or default_run_dir(args)
    settings = run_settings(args)
    hybrid = with_hybrid_overrides(controller.hybrid, dict(settings))
    check_run_folder_hybrid(run_dir, hybrid, args.overwrite)
    # the system, built once: the variant's, stepping under the rules the settings record
    system = get_variant(args.variant).system(args.system)
    announce_perturbations(settings, args.quiet)
    try:
        result = get_learner(args.algo).train(
            system,
            controller,
            args.seed,
            run_dir,
            settings,
            progress=not args.quiet,
            overwrite=args.overwrite,
        )
    except ValueError as error:  # a learner refusing a field: name the flag that set it
        message = with_flag(str(error), flag_changes(args))
        if message == str(error):
            raise
        raise ValueError(message) from error
    print(f"run folder: {result.run_dir}")
    return 0


def set_threads(threads: int | None) -> None:
    """``torch.set_num_threads(threads)`` where ``--threads`` was given."""
    if threads is not None:
        import torch

        torch.set_num_threads(threads)


def run_gym(args: argparse.Namespace) -> int:
    """Train on the gymnasium env of ``gym:ENV_ID`` itself (:func:`leoc.sb3.train_gym`);
    prints the run folder."""
    if args.algo not in MODEL_FREE_ALGOS:
        raise ValueError(
            f"--algo: expected one of {MODEL_FREE_ALGOS} for a gymnasium env (PILCO needs a "
            f"leoc system), found {args.algo!r}"
        )
    check_budget_arguments(args)
    if args.variant != "leoc" or args.profile is not None:
        raise ValueError(
            f"--variant, --profile: expected neither for a gymnasium env (leoc's settings, "
            f"GYM_DEFAULTS), found --variant {args.variant} --profile {args.profile}"
        )
    if getattr(args, "select_on", None) is not None:
        raise ValueError(
            f"--select-on: expected it only for a leoc system (it needs --randomise), found "
            f"--select-on {args.select_on} for {args.system}"
        )
    if getattr(args, "perturb", None) or getattr(args, "randomise", None):
        raise ValueError(
            "--perturb, --randomise: expected neither for a gymnasium env (leoc's perturbations "
            "act on a leoc system's plant), found "
            f"{[*(args.perturb or []), *(args.randomise or [])]}"
        )
    hybrid = hybrid_of(args)
    env_kwargs = env_kwargs_of(getattr(args, "env_option", None))
    from leoc.sb3.gym import train_gym

    env_id = gym_env_id(args.system)
    check_env_kwargs(str(env_id), env_kwargs)
    run_dir = args.out or default_run_dir(args)
    try:
        result = train_gym(
            str(env_id),
            args.algo,
            hybrid,
            args.seed,
            run_dir,
            total_steps=args.steps,
            env_kwargs=env_kwargs,
            progress=not args.quiet,
            overwrite=args.overwrite,
        )
    except ValueError as error:
        message = with_flag(str(error), hybrid_changes(args))
        if message == str(error):
            raise
        raise ValueError(message) from error
    print(f"run folder: {result.run_dir}")
    return 0


def check_env_kwargs(env_id: str, env_kwargs: dict[str, Any]) -> None:
    """Make and reset the env with ``env_kwargs`` once, so that keywords it refuses are one
    line naming ``--env-option`` before anything is written (an unknown env id speaks for
    itself)."""
    if not env_kwargs:
        return
    from leoc.sb3.gym import make_gym_env

    try:
        env = make_gym_env(env_id, env_kwargs)
        env.reset(seed=0)
        env.close()
    except (TypeError, ValueError) as error:
        if isinstance(error, ValueError) and str(error).startswith("env"):
            raise
        reason = f"{type(error).__name__}: {error}".splitlines()[0]
        raise ValueError(
            f"--env-option: expected keywords and values that gymnasium.make({env_id!r}) "
            f"accepts, found {env_kwargs} ({reason})"
        ) from None


def announce_perturbations(settings: dict[str, Any], quiet: bool) -> None:
    """Say on stdout what a run is trained under, when it is perturbed (not ``quiet``)."""
    record = settings.get("training_perturbations")
    if quiet or not record:
        return
    from leoc.systems import TrainingPerturbations

    spec = TrainingPerturbations.from_dict(record)
    selection = (
        "; model selection on plants of the training distribution"
        if settings.get("selection_plants") == "training"
        else ""
    )
    print(
        f"training under perturbation: {spec.describe()} (evaluations on the nominal "
        f"plant{selection})"
    )
