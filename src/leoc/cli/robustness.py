"""``leoc robustness``: the robustness protocol (noise, delay, actuator gain, torque noise,
friction, parameter errors, pushes) on the LQR and trained controllers."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any, NamedTuple

from leoc.cli._args import SYSTEM_HELP, non_negative_int, positive_int, system_or_run_dir
from leoc.names import ROBUSTNESS_CATEGORIES, ROBUSTNESS_EPISODES, ROBUSTNESS_LEVELS

LINEAR = "linear"
MIN_LEVELS = 2


def levels_count(text: str) -> int:
    """argparse type: an integer >= 2 (a sweep has its nominal end and its maximum)."""
    value = positive_int(text)
    if value < MIN_LEVELS:
        raise argparse.ArgumentTypeError(f"expected an integer >= {MIN_LEVELS}, found {value}")
    return value


def add_parser(commands: Any) -> None:
    """Add the ``robustness`` command to the subparsers ``commands``."""
    parser = commands.add_parser(
        "robustness",
        help="robustness protocol: noise, delay, actuator gain, friction, parameter errors, pushes",
        description="Sweep each perturbation category (observation noise, action delay, "
        "actuator gain, torque noise, viscous and Coulomb friction, parameter errors, pushes) "
        "from none to a level at which the system's LQR fails, run episodes at each level from "
        "the operating region and from the swing-up start, and score each controller by the "
        "share held (leoc's hold test) per category and their mean, after RealAIGym's "
        "leaderboard (docs/user_guide/evaluation.md).",
    )
    parser.add_argument(
        "target",
        nargs="?",
        type=system_or_run_dir,
        metavar="SYSTEM|RUN_DIR",
        help=f"{SYSTEM_HELP}; or a run folder (scored, its system read from it). Optional "
        "with --controller RUN_DIR",
    )
    parser.add_argument(
        "--controller",
        nargs="+",
        metavar="CONTROLLER",
        help="'linear' (the LQR) and/or run folders written by 'leoc train' or printed by "
        "'leoc reproduce', scored side by side on one plant (default: linear for a SYSTEM)",
    )
    parser.add_argument(
        "--action-repeat",
        type=positive_int,
        default=None,
        help="control period of the LQR in simulator steps (default: the run folders' own "
        "period, which they must then share; 1 without run folders)",
    )
    parser.add_argument(
        "--levels",
        type=levels_count,
        default=ROBUSTNESS_LEVELS,
        help=f"levels per category, >= 2 (default {ROBUSTNESS_LEVELS}; the delay has at most one "
        "per whole simulator step)",
    )
    parser.add_argument(
        "--episodes",
        type=positive_int,
        default=ROBUSTNESS_EPISODES,
        help=f"episodes per level from each start kind (default {ROBUSTNESS_EPISODES})",
    )
    parser.add_argument(
        "--categories",
        nargs="+",
        choices=ROBUSTNESS_CATEGORIES,
        metavar="CATEGORY",
        help=f"categories to run (default all: {', '.join(ROBUSTNESS_CATEGORIES)})",
    )
    parser.add_argument("--seed", type=non_negative_int, default=0, help="seed (default 0)")
    _add_output_arguments(parser)
    parser.set_defaults(run=run)


def _add_output_arguments(parser: argparse.ArgumentParser) -> None:
    """What ``leoc robustness`` writes: ``--calibrate``, ``--plot``, ``--output``, ``--json``."""
    parser.add_argument(
        "--calibrate",
        action="store_true",
        help="measure instead where the LQR fails in each category (the default levels' "
        "source) and print the maximum levels that follow",
    )
    parser.add_argument("--plot", type=Path, help="write a PNG of the scores here")
    parser.add_argument("--output", type=Path, help="write the results as JSON here")
    parser.add_argument("--json", action="store_true", help="print the results as JSON")


class Scored(NamedTuple):
    """What ``leoc robustness`` scores: the system's name and the controller specs."""

    system: str
    specs: list[str]


def resolve_scored(target: str | Path | None, controllers: list[str] | None) -> Scored:
    """The system and controllers of ``leoc robustness [SYSTEM|RUN_DIR] [--controller ...]``.

    Raises
    ------
    ValueError
        No system to read, a run trained for another system, or a controller given twice.
    """
    from leoc.experiments.controllers import trained_system

    specs = ([str(target)] if isinstance(target, Path) else []) + list(controllers or [])
    runs = [spec for spec in specs if spec != LINEAR]
    if isinstance(target, str):
        system = target
    elif runs:
        system = trained_system(runs[0])
    else:
        raise ValueError(
            "system: expected a system name or a run folder (e.g. 'leoc robustness pendulum' "
            "or 'leoc robustness runs/pendulum/ddpg_hybrid/seed0'), found neither"
        )
    for spec in runs:
        trained_for = trained_system(spec)
        if trained_for != system:
            raise ValueError(
                f"--controller: expected runs trained for {system!r}, found {spec!r} trained "
                f"for {trained_for!r}"
            )
    repeated = sorted({spec for spec in specs if specs.count(spec) > 1})
    if repeated:
        raise ValueError(f"--controller: expected each controller once, found {repeated} twice")
    return Scored(system, specs or [LINEAR])


def robustness_plant(scored: Scored):
    """The plant every controller runs on: the runs' (their recorded step rules' plant, which
    they must share), else leoc's.

    Raises
    ------
    ValueError
        Runs trained on different plants (one protocol is of one plant).
    """
    from leoc.experiments.controllers import trained_step_rules
    from leoc.systems import make_system
    from leoc.systems.base import DEFAULT_RULES

    plants: dict[Any, list[str]] = {}
    for spec in scored.specs:
        if spec != LINEAR:
            plants.setdefault(trained_step_rules(spec).plant(), []).append(spec)
    if len(plants) > 1:
        found = "; ".join(f"{specs}: {plant}" for plant, specs in plants.items())
        raise ValueError(
            f"--controller: expected runs trained on one plant, found {found}; score them in "
            "separate 'leoc robustness' calls"
        )
    return make_system(scored.system).with_rules(next(iter(plants), DEFAULT_RULES))


def _runs(scored: Scored) -> dict[str, Any]:
    """Spec -> saved controller of every run folder among ``scored``'s specs."""
    from leoc.experiments.controllers import load_trained_controller

    return {
        spec: load_trained_controller(Path(spec), system=scored.system)
        for spec in scored.specs
        if spec != LINEAR
    }


def _controllers(scored: Scored, system, runs: dict, period: int) -> dict[str, tuple[str, Any]]:
    """Label -> (colour key, controller) of every spec: the LQR designed on ``system`` at
    ``period``, or a run's saved controller (``runs``). Labels are distinct: a run folder's
    ``SYSTEM/CONTROLLER/seedN`` or name, else as many trailing path parts as tell them apart."""
    from leoc.cli.simulate import controller_key, controller_label, run_labels
    from leoc.experiments.variants import get_variant

    labels = run_labels(list(runs))
    found = {}
    for spec in scored.specs:
        if spec == LINEAR:
            controller = get_variant("leoc").linear_controller(system, period)
            found[controller_label(spec, period)] = (LINEAR, controller)
        else:
            found[labels[spec]] = (controller_key(spec), runs[spec])
    return found


def lqr_period(requested: int | None, runs: dict[str, Any]) -> int:
    """The LQR's control period: ``requested``, else the runs' own (the closed loop they were
    trained in), else 1 without runs.

    Raises
    ------
    ValueError
        No period requested and runs of different periods (which one the LQR should share is
        the user's choice).
    """
    from leoc.systems.rollout import control_period

    if requested is not None:
        return requested
    periods = {spec: control_period(controller) for spec, controller in runs.items()}
    if len(set(periods.values())) > 1:
        raise ValueError(
            "--action-repeat: expected it for the LQR beside runs of different control "
            f"periods, found none (periods {periods})"
        )
    return next(iter(periods.values()), 1)


def _max_levels(system, period: int, seed: int):
    """The table's maximum levels of ``system``; for a system without an entry, measured with
    its LQR first (said on stderr)."""
    from leoc.evaluation.robustness_protocol import DEFAULT_MAX_LEVELS, measured_max_levels
    from leoc.experiments.variants import get_variant

    if system.name in DEFAULT_MAX_LEVELS:
        return DEFAULT_MAX_LEVELS[system.name]
    print(
        f"leoc robustness: {system.name!r} has no default levels; measuring where its LQR "
        "fails first",
        file=sys.stderr,
    )
    lqr = get_variant("leoc").linear_controller(system, period)
    return measured_max_levels(system, lqr, seed=seed)[0]


def _progress(label: str):
    """A progress callback printing each finished start kind of ``label`` on stderr (every
    category's settings run as one batch per start kind)."""
    import time

    started = [time.perf_counter()]

    def report(kind: str, done: int, total: int) -> None:
        seconds = time.perf_counter() - started[0]
        print(f"  {label}: {kind} starts ({done}/{total}, {seconds:.1f} s)", file=sys.stderr)
        started[0] = time.perf_counter()

    return report


def _calibrate(args: argparse.Namespace, system, period: int) -> int:
    """``--calibrate``: where the LQR fails in each category, and the levels that follow."""
    import dataclasses

    from leoc.evaluation.robustness_protocol import CALIBRATION_EPISODES, measured_max_levels
    from leoc.experiments.variants import get_variant

    lqr = get_variant("leoc").linear_controller(system, period)
    levels, found = measured_max_levels(system, lqr, seed=args.seed)
    record = {
        "system": system.name,
        "episodes": CALIBRATION_EPISODES,
        "failure_levels": {name: entry._asdict() for name, entry in found.items()},
        "max_levels": dataclasses.asdict(levels),
    }
    if args.json:
        print(json.dumps(record, indent=1))
        return 0
    print(
        f"Where the LQR of {system.name} (period {period}) holds none of "
        f"{CALIBRATION_EPISODES} operating-region episodes (seed {args.seed}):"
    )
    for name, entry in found.items():
        note = "" if entry.found else " (holds some up to the search's end)"
        print(f"  {name:<18} {entry.level:<10.4g} -> max level {levels.level(name):g}{note}")
    return 0


def run(args: argparse.Namespace) -> int:
    import time

    import torch

    from leoc.evaluation.robustness_protocol import (
        CATEGORY_NAMES,
        DEFAULT_MAX_LEVELS,
        run_protocol,
    )
    from leoc.experiments.controllers import trained_under

    torch.set_num_threads(1)
    started = time.perf_counter()
    scored = resolve_scored(args.target, args.controller)
    system = robustness_plant(scored)
    runs = _runs(scored)
    period = args.action_repeat or 1  # the LQR's, where neither scored nor calibrating with it
    if LINEAR in scored.specs or args.calibrate or system.name not in DEFAULT_MAX_LEVELS:
        period = lqr_period(args.action_repeat, runs)
    if args.calibrate:
        return _calibrate(args, system, period)
    controllers = _controllers(scored, system, runs, period)
    max_levels = _max_levels(system, period, args.seed)
    results = {}
    for label, (_, controller) in controllers.items():
        print(f"leoc robustness: {label} on {system.name}", file=sys.stderr)
        results[label] = run_protocol(
            system,
            controller,
            label,
            levels=args.levels,
            episodes=args.episodes,
            categories=args.categories or CATEGORY_NAMES,
            seed=args.seed,
            max_levels=max_levels,
            progress=_progress(label),
        )
    report = _report(args, system, results, controllers)
    report["trained_under"] = trained_under(scored.specs)  # the protocol's plant is nominal
    if args.plot:
        from leoc.evaluation.plots.robustness_protocol import plot_protocol_scores

        keys = {label: key for label, (key, _) in controllers.items()}
        report["plot"] = str(plot_protocol_scores(results, args.plot, keys))
    report["seconds"] = time.perf_counter() - started
    if args.output:
        from leoc.io import write_json_atomic

        report["output"] = str(write_json_atomic(args.output, report))
    if args.json:
        print(json.dumps(report, indent=1))
        return 0
    _print_scores(report, results)
    return 0


def _report(args: argparse.Namespace, system, results: dict, controllers: dict) -> dict:
    """The results of ``leoc robustness`` as ``--json`` prints and ``--output`` writes them."""
    import dataclasses

    return {
        "system": system.name,
        "plant": dataclasses.asdict(system.rules.plant()),
        "seed": args.seed,
        "levels": args.levels,
        "episodes": args.episodes,
        "controllers": {label: key for label, (key, _) in controllers.items()},
        "scores": {label: result.as_dict()["scores"] for label, result in results.items()},
        "results": {label: result.as_dict() for label, result in results.items()},
    }


def _print_scores(report: dict, results: dict) -> None:
    """The score table: per category and controller the share held (from the operating region
    / from the swing-up start), then the robustness score."""
    first = next(iter(results.values()))
    print(
        f"Robustness protocol on {report['system']} (protocol seed {report['seed']}; up to "
        f"{report['levels']} levels per category, {report['episodes']} episodes per level from "
        "the operating region and as many from the swing-up start; held: leoc's hold test)"
    )
    print("score = share held, all starts (operating region / swing-up start)")
    labels = list(results)
    width = max(24, *(len(label) + 2 for label in labels))
    print(f"{'category':<18} {'max level':>9}  " + "".join(f"{label:<{width}}" for label in labels))
    rows = [(c.name, f"{c.max_level:g}") for c in first.categories] + [("robustness", "")]
    for name, max_level in rows:
        cells = []
        for label in labels:
            scores = report["scores"][label]
            key = name
            cells.append(
                f"{scores['all'][key]:.3f} ({scores['operating_region'][key]:.2f} / "
                f"{scores['swing_up'][key]:.2f})"
            )
        print(f"{name:<18} {max_level:>9}  " + "".join(f"{cell:<{width}}" for cell in cells))
    for key in ("plot", "output"):
        if key in report:
            print(f"{'figure' if key == 'plot' else 'results'} written to {report[key]}")
    print(f"({report['seconds']:.1f} s)")
