"""``leoc roa``: certify the LQR's region of attraction and measure empirical basins."""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path
from typing import Any

from leoc.cli._args import (
    SYSTEM_HELP,
    non_negative_int,
    positive_float,
    positive_int,
    system_name,
)
from leoc.cli.lqr import print_matrix
from leoc.cli.simulate import load_controller


def add_parser(commands: Any) -> None:
    """Add the ``roa`` command to the subparsers ``commands``."""
    roa = commands.add_parser(
        "roa",
        help="certify the LQR's region of attraction and measure empirical basins",
        description="Prove the largest sublevel set of V = z^T P z (P from the LQR design) on "
        "which V decreases along the nonlinear, saturated, held closed loop, inside the allowed "
        "region (interval arithmetic on adaptively bisected boxes; the sampled estimate after "
        "Najafi et al. 2016, printed beside it, is its target), and simulate seeded starts in a "
        "box for the LQR and each --controller.",
    )
    roa.add_argument(
        "system",
        nargs="?",
        type=system_name,
        metavar="SYSTEM",
        help=f"{SYSTEM_HELP}; optional with --controller (read from the run folders)",
    )
    roa.add_argument(
        "--controller",
        nargs="+",
        help="run folders written by 'leoc train' or printed by 'leoc reproduce' (basins of "
        "each); the LQR is certified on their plant (the integrator they were trained with)",
    )
    roa.add_argument(
        "--action-repeat",
        type=positive_int,
        default=1,
        help="control period of the LQR in simulator steps (default 1)",
    )
    roa.add_argument(
        "--samples",
        type=positive_int,
        default=100_000,
        help="samples per round of the sampled estimate (default 100000)",
    )
    roa.add_argument(
        "--starts", type=positive_int, default=2000, help="basin starts (default 2000)"
    )
    roa.add_argument(
        "--box",
        type=positive_float,
        nargs="+",
        help="basin box half-widths per state, in the state's units (rad, rad/s, m, m/s)",
    )
    roa.add_argument("--seed", type=non_negative_int, default=0, help="seed (default 0)")
    roa.add_argument(
        "--slice-points",
        type=positive_int,
        default=41,
        help="grid points per axis of the plot slice (default 41)",
    )
    roa.add_argument("--plot", type=Path, help="write a PNG of the basin slices here")
    roa.add_argument("--json", action="store_true", help="print the results as JSON")
    roa.set_defaults(run=run)


ROA_SLICES = {"pendulum": (0, 1), "cartpole": (2, 3), "mountaincar": (0, 1)}
"""2-D slice of each system's basin plot: theta vs theta_dot, or x vs x_dot."""
LEGACY_PLANT_NOTE = "; on gym 0.17's integrator, the plant the runs were trained on"
ROA_PLOT_MARGIN = 1.25
"""The plot's slice box reaches at least this factor times the certified set's extent."""


def roa_plant(args: argparse.Namespace):
    """The system ``leoc roa`` certifies and samples: ``SYSTEM`` on leoc's plant, or the plant
    the ``--controller`` runs were trained on (:meth:`~leoc.systems.StepRules.plant`: reward-only
    training choices dropped), which every run must share; fills ``args.system`` from the runs
    when it was left out.

    Raises
    ------
    ValueError
        Neither a system nor a run given, a run trained for another system, or runs trained on
        different plants (one certificate is of one plant).
    """
    from leoc.experiments.controllers import trained_step_rules, trained_system
    from leoc.systems import make_system
    from leoc.systems.base import DEFAULT_RULES

    runs = list(args.controller or [])
    if args.system is None:
        if not runs:
            raise ValueError(
                "system: expected a system name or --controller RUN_DIR (e.g. 'leoc roa "
                "pendulum' or 'leoc roa --controller runs/pendulum_ddpg_hybrid_seed0'), found "
                "neither"
            )
        args.system = trained_system(runs[0])
    plants = {}
    for spec in runs:
        trained_for = trained_system(spec)
        if trained_for != args.system:
            raise ValueError(
                f"--controller: {spec!r} was trained for {trained_for!r}, not for {args.system!r}"
            )
        plants.setdefault(trained_step_rules(spec).plant(), []).append(spec)
    if len(plants) > 1:
        described = "; ".join(
            f"{', '.join(map(repr, specs))} on {dataclasses.asdict(plant)}"
            for plant, specs in plants.items()
        )
        raise ValueError(
            f"--controller: expected runs trained on one plant (a certificate is of one plant), "
            f"found {described}; certify them in separate 'leoc roa' calls"
        )
    plant = next(iter(plants), DEFAULT_RULES)
    return make_system(args.system).with_rules(plant)


def _roa_controllers(args: argparse.Namespace, design) -> dict:
    """The LQR (at the design's period) and every ``--controller`` run folder, by label."""
    from leoc.control import lqr_closed_loop

    controllers = {f"LQR (period {design.action_repeat})": lqr_closed_loop(design)}
    for spec in args.controller or []:
        controllers[Path(spec).name] = load_controller(spec, args.system)
    return controllers


def run(args: argparse.Namespace) -> int:
    import time

    import numpy as np
    import torch

    from leoc.control import (
        basin_starts,
        box_fraction,
        certified_set_check,
        certify_lqr,
        default_basin_box,
        design_lqr,
        empirical_basin,
        plot_basins,
        slice_grid,
    )

    torch.set_num_threads(1)
    started = time.perf_counter()
    system = roa_plant(args)
    design = design_lqr(system, action_repeat=args.action_repeat)
    certificate = certify_lqr(system, design, samples=args.samples, seed=args.seed)
    box = default_basin_box(system) if args.box is None else np.asarray(args.box, dtype=float)
    fraction, error = box_fraction(certificate, box, seed=args.seed)
    starts = basin_starts(system, box, args.starts, seed=args.seed)
    basins = {}
    for label, controller in _roa_controllers(args, design).items():
        basin = empirical_basin(system, controller, starts, box=box)
        inside = certified_set_check(system, controller, certificate, args.starts, args.seed)
        basins[label] = {
            "controller": controller,
            "box_held": basin.fraction,
            "certified_set_held": inside.fraction,
        }
    report = {
        "system": args.system,
        "plant": dataclasses.asdict(system.rules.plant()),
        "action_repeat": design.action_repeat,
        "certificate": certificate.summary(),
        "box": box.tolist(),
        "box_fraction": fraction,
        "box_fraction_stderr": error,
        "basin_starts": args.starts,
        "basins": {
            label: {key: value for key, value in entry.items() if key != "controller"}
            for label, entry in basins.items()
        },
    }
    if args.plot:
        dims = ROA_SLICES.get(args.system, (0, 1))
        # The slice box covers the certified ellipse too, so the plot shows its boundary.
        plot_box = np.maximum(box, ROA_PLOT_MARGIN * certificate.extent)
        grid = slice_grid(system, dims, plot_box, args.slice_points)
        slices = {
            label: empirical_basin(system, entry["controller"], grid, box=plot_box)
            for label, entry in basins.items()
        }
        report["plot"] = str(
            plot_basins(system, certificate, slices, dims, args.slice_points, args.plot, box=box)
        )
    report["seconds"] = time.perf_counter() - started
    if args.json:
        print(json.dumps(report, indent=1))
        return 0
    _print_roa(system, certificate, report)
    return 0


def _print_roa(system, certificate, report: dict) -> None:
    names = ", ".join(system.state_names)
    print(
        f"Region of attraction of the LQR on {report['system']} (control period "
        f"{report['action_repeat']} step(s), dt = {system.dt} s"
        f"{LEGACY_PLANT_NOTE if report['plant']['legacy_integrator'] else ''}"
        f"); state: {names}"
    )
    print("V(x) = z^T P z, z = x - a (angles wrapped); certified: V(F(x)) < V(x) on 0 < V <= rho")
    print_matrix("P", certificate.P)
    from leoc.control.roa import describe_certificate

    for line in describe_certificate(system, certificate):
        print(line)
    box = ", ".join(
        f"{name} +/- {width:.4g}"
        for name, width in zip(system.state_names, report["box"], strict=True)
    )
    print(
        f"box: {box}; the certified set covers {report['box_fraction']:.1%} "
        f"(+/- {report['box_fraction_stderr']:.1%}) of it"
    )
    print(f"empirical basins ({report['basin_starts']} seeded starts, converge and hold):")
    for label, entry in report["basins"].items():
        print(
            f"  {label}: {entry['box_held']:.1%} of the box; {entry['certified_set_held']:.1%} of "
            "the certified set"
        )
    if "plot" in report:
        print(f"figure written to {report['plot']}")
    print(f"({report['seconds']:.1f} s)")
