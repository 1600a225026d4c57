"""``leoc simulate``: impulse or step response of a controller from the operating point."""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path
from typing import Any, NamedTuple

from leoc.cli._args import (
    SYSTEM_HELP,
    add_env_option,
    non_negative_int,
    positive_float,
    positive_int,
    system_or_run_dir,
)
from leoc.cli.lqr import METHODS
from leoc.names import GYM_PREFIX, METRIC_SET_NAMES, VARIANT_NAMES, gym_env_id

LINEAR = "linear"


def add_parser(commands: Any) -> None:
    """Add the ``simulate`` command to the subparsers ``commands``."""
    simulate = commands.add_parser(
        "simulate",
        help="impulse or step response of a controller from the operating point",
        description="Run the impulse or step test of a controller from the operating point and "
        "print its steady-state error, overshoot, peak deviation and settling time. "
        "'leoc simulate RUN_DIR' simulates the controller of a run folder on the system it "
        "was trained for. 'leoc simulate gym:ENV_ID' (the env's LQR) and 'leoc simulate "
        "RUN_DIR' of 'leoc train gym:ENV_ID' run the test on the gymnasium env itself, from its "
        "operating state: the impulse forces the first action to --magnitude (default the "
        "action limit), the step adds --magnitude (default 10%% of the limit) to every action; "
        "a trained controller is printed beside its LQR, with their largest difference.",
    )
    _add_controller_arguments(simulate)
    _add_test_arguments(simulate)
    _add_gym_arguments(simulate)
    _add_output_arguments(simulate)
    simulate.set_defaults(run=run)


def _add_controller_arguments(parser: argparse.ArgumentParser) -> None:
    """What ``leoc simulate`` runs: ``SYSTEM|RUN_DIR``, ``--controller``, ``--action-repeat``."""
    parser.add_argument(
        "target",
        nargs="?",
        type=simulate_target,
        metavar="SYSTEM|RUN_DIR",
        help=f"{SYSTEM_HELP}; or {GYM_PREFIX}ENV_ID, a gymnasium env (its LQR); or a run "
        "folder (its system is read from it). Optional with --controller RUN_DIR",
    )
    parser.add_argument(
        "--controller",
        default=LINEAR,
        help="'linear' (the LQR) or a run folder written by 'leoc train' or printed by "
        "'leoc reproduce' (default: linear); a trained controller runs at its trained period",
    )
    parser.add_argument(
        "--action-repeat",
        type=positive_int,
        default=1,
        help="control period of the linear controller in simulator steps (its LQR is designed "
        "for it; PILCO's period is 2 on the pendulum, 3 on cartpole and 3 on mountaincar); "
        "default 1",
    )


def _add_test_arguments(parser: argparse.ArgumentParser) -> None:
    """How the response is measured: band, test, length, LQR design, variant, metric set."""
    parser.add_argument(
        "--band",
        type=positive_float,
        help="absolute settling band (deg or m); default 2%% of the peak error",
    )
    parser.add_argument("--test", choices=("impulse", "step"), default="impulse")
    parser.add_argument(
        "--steps",
        type=positive_int,
        help="episode length (default: the variant's, 200; the authors' cart-pole record: 400)",
    )
    parser.add_argument(
        "--method",
        choices=METHODS,
        help="LQR design of the linear controller (default: the variant's; leoc: discrete)",
    )
    parser.add_argument(
        "--variant",
        choices=VARIANT_NAMES,
        help="implementation: leoc's defaults, or the authors' (nrjc/LEOC: their LQR scaled by "
        "u_max with a sin squash, their env rules); default leoc, or for a run folder the "
        "variant whose step rules it was trained under (another is refused: it would simulate "
        "a different plant)",
    )
    parser.add_argument(
        "--metrics",
        choices=METRIC_SET_NAMES,
        default="leoc",
        help="metric set: leoc's (final-window mean, band 2%% of the peak) or the authors' "
        "(arcsin(sin theta), last sample, band +/- pi/180); default leoc",
    )


def _add_gym_arguments(parser: argparse.ArgumentParser) -> None:
    """The test's options on a gymnasium env (``gym:ENV_ID`` or its run folder)."""
    group = parser.add_argument_group("gymnasium envs (gym:ENV_ID or its run folder only)")
    group.add_argument(
        "--magnitude",
        type=float,
        help="the impulse's forced action (default the action space's upper limit) or the "
        "step's offset (default 10%% of it)",
    )
    group.add_argument(
        "--main-index",
        type=non_negative_int,
        help="state entry recorded (default: the pole angle qpos[1] in deg for the inverted "
        "pendulums, theta for Pendulum-v1, else entry 0 in the state's units)",
    )
    add_env_option(group, f"{GYM_PREFIX}ENV_ID only (a run folder uses its own)")


def simulate_target(text: str) -> str | Path:
    """argparse type of ``leoc simulate``'s target: ``gym:ENV_ID`` (the id is checked when
    the env is made), a system name or a run folder (:func:`system_or_run_dir`)."""
    if text.startswith(GYM_PREFIX):
        try:
            gym_env_id(text)
        except ValueError as error:
            raise argparse.ArgumentTypeError(str(error)) from None
        return text
    return system_or_run_dir(text)


def _add_output_arguments(parser: argparse.ArgumentParser) -> None:
    """What ``leoc simulate`` writes besides the printed metrics: figure, animation, JSON."""
    parser.add_argument("--plot", type=Path, help="write a PNG of the response here")
    parser.add_argument(
        "--video",
        type=Path,
        metavar="FILE",
        help="write an animation here (.gif, or .mp4 where ffmpeg is installed): the swing-up "
        "from the system's swing-up start, then the impulse response, with r(x) shown for a "
        "hybrid controller",
    )
    parser.add_argument(
        "--json", action="store_true", help="print the metrics and e(t) as JSON instead"
    )


class Target(NamedTuple):
    """What to simulate: the system's name and the controller ('linear' or a run folder)."""

    system: str
    controller: str


def resolve_target(target: str | Path | None, controller: str) -> Target:
    """The system and controller of ``leoc simulate [SYSTEM|RUN_DIR] [--controller C]``.

    Raises
    ------
    ValueError
        No system given and none to read from a run folder, or two controllers given.
    """
    from leoc.experiments.controllers import trained_system

    if isinstance(target, Path):
        if controller != LINEAR:
            raise ValueError(
                f"controller: expected one controller, found the run folder {str(target)!r} "
                f"and --controller {controller!r}"
            )
        return Target(trained_system(target), str(target))
    if target is None:
        if controller == LINEAR:
            raise ValueError(
                "system: expected a system name or a run folder (e.g. 'leoc simulate pendulum' "
                "or 'leoc simulate runs/pendulum/ddpg_hybrid/seed0'), found neither"
            )
        return Target(trained_system(controller), controller)
    return Target(target, controller)


def load_controller(
    spec: str,
    system_name: str,
    method: str | None = None,
    action_repeat: int = 1,
    variant: str = "leoc",
):
    """``linear`` (the variant's linear reference of the system, designed for and run at
    ``action_repeat``; ``method`` overrides its LQR design) or a run folder written by
    ``leoc train`` or printed by ``leoc reproduce`` (at its trained period)."""
    import dataclasses

    from leoc.experiments.variants import get_variant

    chosen = get_variant(variant)
    if spec == LINEAR:
        if method is not None:
            chosen = dataclasses.replace(chosen, lqr_method=method)
        return chosen.linear_controller(chosen.system(system_name), action_repeat)
    from leoc.experiments.controllers import load_trained_controller

    return load_trained_controller(Path(spec), system=system_name)


def controller_key(spec: str) -> str:
    """The controller's name for its colour: ``linear``, the CONTROLLER of a reproduce run
    folder ``.../SYSTEM/CONTROLLER/seedN``, else ``trained``."""
    if spec == LINEAR:
        return LINEAR
    parts = Path(spec).resolve().parts
    if len(parts) >= 3 and parts[-1].startswith("seed"):
        return parts[-2]
    return "trained"


def controller_label(spec: str, period: int) -> str:
    """The legend label of a simulated controller: the LQR and its period, or the run folder's
    :func:`run_label`."""
    if spec == LINEAR:
        return f"LQR (period {period} step{'s' if period > 1 else ''})"
    return run_label(spec)


def run_label(spec: str) -> str:
    """A run folder's label: ``SYSTEM/CONTROLLER/seedN`` (a reproduce run) or its folder name."""
    parts = Path(spec).resolve().parts
    if len(parts) >= 3 and parts[-1].startswith("seed"):
        return "/".join(parts[-3:])
    return parts[-1]


def run_labels(specs: list[str]) -> dict[str, str]:
    """A distinct label per run folder, the one ``simulate``, ``roa`` and ``robustness`` name
    runs by: :func:`run_label` where those are distinct, else as many trailing path parts as
    make them distinct (``seed0/train`` beside ``seed1/train``)."""
    labels = {spec: run_label(spec) for spec in specs}
    if len(set(labels.values())) == len(labels):
        return labels
    parts = {spec: Path(spec).resolve().parts for spec in specs}
    for depth in range(1, max((len(p) for p in parts.values()), default=1) + 1):
        labels = {spec: "/".join(path[-depth:]) for spec, path in parts.items()}
        if len(set(labels.values())) == len(labels):
            return labels
    return {spec: str(Path(spec).resolve()) for spec in specs}


def simulated_variant(target: Target, requested: str | None) -> str:
    """The variant whose settings (episode length, the name reported) ``target`` is simulated
    with: ``requested`` (default leoc) for the LQR; for a run folder, a variant with the run's
    plant (:meth:`~leoc.systems.StepRules.plant`: its dynamics; which state a reward was taken
    on or what an exit paid are training choices and never block evaluation), by default the
    one whose rules equal the run's, else leoc's if it has the run's plant. The run itself is
    always stepped under its own recorded rules (:func:`simulated_system`).

    Raises
    ------
    ValueError
        ``requested`` names a variant on another plant than the run's, or no variant has the
        run's plant.
    """
    from leoc.experiments.controllers import trained_step_rules
    from leoc.experiments.variants import VARIANTS

    if target.controller == LINEAR:
        return requested or "leoc"
    rules = trained_step_rules(target.controller)
    same_plant = [
        name for name, v in VARIANTS.items() if v.rules_for(target.system).plant() == rules.plant()
    ]
    if requested is None:
        exact = [name for name in same_plant if VARIANTS[name].rules_for(target.system) == rules]
        if exact or same_plant:
            return (exact or same_plant)[0]
    elif requested in same_plant:
        return requested
    found = f"the {requested} variant's plant" if requested else "no variant's plant"
    raise ValueError(
        f"--variant: the controller in {target.controller!r} was trained on {target.system} "
        f"under {_describe_plant(rules)}; {found} differs, and simulating it there would "
        "measure another plant than the one it was trained on"
        + (f" (leave --variant out, or use {' or '.join(same_plant)})" if same_plant else "")
    )


def _describe_plant(rules) -> str:
    """The plant fields of ``rules`` in words, for an error message."""
    plant = rules.plant()
    return "gym 0.17's integrator" if plant.legacy_integrator else "leoc's integrator"


def simulated_system(target: Target, variant):
    """The system ``target`` is simulated on: a run folder's own plant under its own recorded
    step rules (:func:`~leoc.experiments.controllers.trained_plant`); the variant's system for
    the LQR."""
    if target.controller == LINEAR:
        return variant.system(target.system)
    from leoc.experiments.controllers import trained_plant

    return trained_plant(target.controller)


def _trained_under(target: Target) -> Any:
    """What ``target``'s controller was trained under (nominal for the LQR)."""
    from leoc.systems import TrainingPerturbations

    if target.controller == LINEAR:
        return TrainingPerturbations()
    from leoc.experiments.controllers import trained_perturbations

    return trained_perturbations(target.controller)


def _selection_plants(target: Target) -> str:
    """Which plants ``target``'s model selection judged on (``nominal`` for the LQR)."""
    if target.controller == LINEAR:
        return "nominal"
    from leoc.experiments.controllers import trained_selection_plants

    return trained_selection_plants(target.controller)


def _json_report(
    args: argparse.Namespace, target: Target, system: Any, result: Any, period: int
) -> dict[str, Any]:
    """What ``--json`` prints: the test, its plant and rules, what a run was trained under
    (``training_perturbations``, {} for the LQR and nominal runs: the test itself runs on the
    nominal plant) and which plants chose its kept actor (``selection_plants``), metrics and
    record."""
    return {
        "system": target.system,
        "controller": target.controller,
        "test": args.test,
        "variant": args.variant,
        "step_rules": dataclasses.asdict(system.rules),
        "training_perturbations": _trained_under(target).as_dict(),
        "selection_plants": _selection_plants(target),
        "metrics_set": args.metrics,
        "action_repeat": period,
        "metrics": result.metrics._asdict(),
        "deviation": result.deviation.tolist(),
        "total_reward": result.trajectory.total_reward,
    }


def run(args: argparse.Namespace) -> int:
    from leoc.cli._gym import check_gym_options, run_gym_simulate
    from leoc.evaluation.rollout import control_period, response_test
    from leoc.experiments.variants import get_variant

    if args.band is not None and args.metrics == "authors":
        raise ValueError("--band: the authors' metrics fix the band (pi/180); leave --band out")
    target = resolve_target(args.target, args.controller)
    if gym_env_id(target.system) is not None:
        return run_gym_simulate(args, target.system, target.controller)
    check_gym_options(args, False)
    args.variant = simulated_variant(target, args.variant)
    variant = get_variant(args.variant)
    system = simulated_system(target, variant)
    controller = load_controller(
        target.controller, target.system, args.method, args.action_repeat, args.variant
    )
    if args.steps is None:
        args.steps = variant.steps_for(target.system)
    result = response_test(
        system, controller, args.test, steps=args.steps, band=args.band, metric_set=args.metrics
    )
    period = control_period(controller)
    if args.video:
        from leoc.evaluation.video import write_video

        label = f"{controller_label(target.controller, period)} on {target.system}"
        video = write_video(system, controller, args.video, args.steps, label)
        print(f"animation written to {video}", file=sys.stderr if args.json else sys.stdout)
    if args.json:
        print(json.dumps(_json_report(args, target, system, result, period)))
        return 0
    _print_metrics(args, target, system, result, period)
    if args.plot:
        from leoc.evaluation.plots import plot_responses

        key = controller_key(target.controller)
        record = {
            "deviation": result.deviation,
            "terminated": result.metrics.terminated,
            "settled": result.metrics.settled,
        }
        path = plot_responses(
            {target.system: {args.test: {key: [record]}}},
            args.plot,
            labels={key: controller_label(target.controller, period)},
        )
        print(f"figure written to {path}")
    return 0


def _print_metrics(args: argparse.Namespace, target: Target, system, result, period: int) -> None:
    metrics = result.metrics
    unit = "deg" if system.main_in_degrees else "m"
    settling = (
        "not settled"
        if metrics.settling_time is None
        else f"{metrics.settling_time} steps ({metrics.settling_seconds:.3g} s)"
    )
    band = (
        f"{metrics.band:.3g} {unit}, absolute"
        if metrics.band_fraction is None
        else f"{metrics.band:.3g} {unit} = {metrics.band_fraction:.0%} of the peak error"
    )
    print(
        f"{args.test} response of {target.controller} on {target.system} ({args.steps} steps, "
        f"control period {period} step{'s' if period > 1 else ''}; variant {args.variant}, "
        f"{args.metrics} metrics)"
    )
    print(f"  steady-state error: {metrics.steady_state_error:.6g} {unit}")
    print(f"  overshoot:          {metrics.overshoot:.6g} {unit}")
    print(f"  peak deviation:     {metrics.peak_deviation:.6g} {unit}")
    print(f"  settling time:      {settling} (band {band})")
    print(f"  terminated:         {'yes' if metrics.terminated else 'no'}")
    print(f"  return:             {result.trajectory.total_reward:.4f}")
    trained_under = _trained_under(target)
    if not trained_under.is_nominal:
        print(f"  trained under:      {trained_under.describe()} (simulated on the nominal plant)")
    if _selection_plants(target) == "training":
        print("  kept actor:         chosen on plants of the training distribution")
