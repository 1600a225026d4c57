"""``leoc roa``: certify the LQR's region of attraction and measure empirical basins."""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path
from typing import Any, NamedTuple

from leoc.cli._args import (
    SYSTEM_HELP,
    non_negative_int,
    positive_float,
    positive_int,
    system_name,
)
from leoc.cli.lqr import print_matrix
from leoc.cli.simulate import load_controller, run_labels
from leoc.names import GYM_PREFIX, LYAPUNOV_CHOICES


def add_parser(commands: Any) -> None:
    """Add the ``roa`` command to the subparsers ``commands``."""
    roa = commands.add_parser(
        "roa",
        help="certify the LQR's region of attraction and measure empirical basins",
        description="Prove the largest sublevel set of V = z^T P z (P from the LQR design) on "
        "which V decreases along the nonlinear, saturated, held closed loop, inside the allowed "
        "region (interval arithmetic on adaptively bisected boxes; the sampled estimate after "
        "Najafi et al. 2016, printed beside it, is its target), and simulate seeded starts in a "
        "box for the LQR and each --controller. With --controller, the LQR is the runs' own: "
        "the design method in their config, their control period and their output squash.",
    )
    roa.add_argument(
        "system",
        nargs="?",
        type=roa_system,
        metavar="SYSTEM",
        help=f"{SYSTEM_HELP}; optional with --controller (read from the run folders)",
    )
    roa.add_argument(
        "--controller",
        nargs="+",
        help="run folders written by 'leoc train' or printed by 'leoc reproduce' (basins of "
        "each); the LQR certified is the one they were trained with (its design method, "
        "control period and squash), on their plant (the integrator they were trained with)",
    )
    roa.add_argument(
        "--action-repeat",
        type=positive_int,
        help="control period of the LQR in simulator steps (default 1; with --controller the "
        "runs' own period, and another one is refused)",
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
    _add_proof_arguments(roa)
    roa.add_argument("--plot", type=Path, help="write a PNG of the basin slices here")
    roa.add_argument("--json", action="store_true", help="print the results as JSON")
    roa.set_defaults(run=run)


def _add_proof_arguments(roa: argparse.ArgumentParser) -> None:
    """``--prove`` and its options: the trained controllers' own proved regions."""
    roa.add_argument(
        "--prove",
        action="store_true",
        help="also prove each --controller's own region of attraction: its equilibrium near a, "
        "and the largest level set of a quadratic V (the LQR's P or its own linearisation's "
        "Lyapunov matrix, whichever proves more) on which V decreases along its closed loop "
        "(interval arithmetic through the trained network)",
    )
    roa.add_argument(
        "--lyapunov",
        choices=LYAPUNOV_CHOICES,
        default="best",
        help="with --prove: the V to prove with (default best: both, the larger proved set)",
    )
    roa.add_argument(
        "--proof-seconds",
        type=positive_float,
        default=480.0,
        help="with --prove: wall-clock budget of each controller's box search (default 480; "
        "past it the level proved so far is reported, limited by budget)",
    )
    roa.add_argument(
        "--device",
        default="cpu",
        help="with --prove: where the boxes are evaluated, cpu (default) or cuda[:N] (a GPU "
        "through torch's CUDA build; the equilibrium search and the sampled estimates stay on "
        "the CPU)",
    )


def roa_system(text: str) -> str:
    """argparse type of ``leoc roa``'s SYSTEM: a system name; ``gym:ENV_ID`` is refused with
    the reason (no interval model of a gymnasium env exists)."""
    if text.startswith(GYM_PREFIX):
        raise argparse.ArgumentTypeError(
            f"expected a leoc system, found the gymnasium env {text!r}: it has no interval "
            "model, so no region of attraction can be proved (a run of 'leoc train "
            f"{text}' records a sampled level in its design.json)"
        )
    return system_name(text)


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
                "pendulum' or 'leoc roa --controller runs/pendulum/ddpg_hybrid/seed0'), found "
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


class CertifiedLQR(NamedTuple):
    """Which LQR ``leoc roa`` designs and certifies: that of the ``--controller`` runs, else
    leoc's discrete design at ``--action-repeat`` clipped by the actuator."""

    method: str
    """``method`` of :func:`leoc.control.design_lqr` (a run's config ``lqr_method``)."""
    action_repeat: int
    """Control period in simulator steps (a run's: that of its loaded controller)."""
    saturation: str
    """Squash of the linear part, :func:`leoc.policies.hybrid.saturated_lqr`'s ``saturation``:
    ``clip`` (the actuator's, in the step) or a run's own (PILCO: ``sin``)."""


DEFAULT_LQR_METHOD = "discrete"
"""The LQR of ``leoc roa SYSTEM`` and of a run whose config records no ``lqr_method``."""
DEFAULT_ACTION_REPEAT = 1
"""The control period of ``leoc roa SYSTEM`` without ``--action-repeat``."""
LINEAR_PART_RTOL = 1e-9
LINEAR_PART_ATOL = 1e-12
"""Agreement of a run's saved linear part with its redesigned LQR (float64 copies of one
design: equal up to rounding)."""


def run_lqr(spec: str, controller) -> CertifiedLQR:
    """The LQR the run in ``spec`` (loaded as ``controller``) was trained with: its config's
    ``lqr_method``, the loaded controller's control period and output squash."""
    from leoc.experiments.controllers import trainer_dir
    from leoc.policies.hybrid import output_saturation
    from leoc.systems.rollout import control_period
    from leoc.training import read_config

    method = read_config(trainer_dir(spec)).get("lqr_method") or DEFAULT_LQR_METHOD
    return CertifiedLQR(str(method), control_period(controller), output_saturation(controller))


def certified_lqr_choice(args: argparse.Namespace, runs: dict) -> CertifiedLQR:
    """The one LQR of ``runs`` (run folder -> loaded controller), or leoc's at
    ``--action-repeat`` without runs.

    Raises
    ------
    ValueError
        The runs differ in a choice (one line naming it and each run's value), or an explicit
        ``--action-repeat`` is not the runs' period.
    """
    if not runs:
        repeat = DEFAULT_ACTION_REPEAT if args.action_repeat is None else args.action_repeat
        return CertifiedLQR(DEFAULT_LQR_METHOD, repeat, "clip")
    choices = {spec: run_lqr(spec, controller) for spec, controller in runs.items()}
    for field in CertifiedLQR._fields:
        values = {spec: getattr(choice, field) for spec, choice in choices.items()}
        if len(set(values.values())) > 1:
            found = ", ".join(f"{spec!r}: {value!r}" for spec, value in values.items())
            raise ValueError(
                f"--controller: expected runs trained with one LQR (a certificate is of one "
                f"closed loop), found {field} {found}; certify them in separate 'leoc roa' calls"
            )
    chosen = next(iter(choices.values()))
    if args.action_repeat is not None and args.action_repeat != chosen.action_repeat:
        raise ValueError(
            f"--action-repeat: the runs' LQR runs at period {chosen.action_repeat}, found "
            f"{args.action_repeat}; leave it out to certify the LQR they were trained with"
        )
    return chosen


def _check_linear_part(spec: str, controller, design, lqr: CertifiedLQR) -> None:
    """Refuse when the hybrid in ``controller`` has another linear part than ``design``'s
    ``W, b`` (a run whose LQR cannot be redesigned from its config); baselines have none."""
    import numpy as np

    from leoc.policies import HybridPolicy

    hybrid = next((m for m in controller.modules() if isinstance(m, HybridPolicy)), None)
    if hybrid is None:
        return
    gain = hybrid.linear.W.detach().cpu().numpy()
    bias = hybrid.linear.b.detach().cpu().numpy()
    if not (
        np.allclose(gain, design.W, rtol=LINEAR_PART_RTOL, atol=0.0)
        and np.allclose(bias, design.b, rtol=LINEAR_PART_RTOL, atol=LINEAR_PART_ATOL)
    ):
        raise ValueError(
            f"--controller: the linear part of {spec!r} (W = {gain.tolist()}) is not the "
            f"{lqr.method!r} LQR at period {lqr.action_repeat} (W = {design.W.tolist()}); "
            "its LQR cannot be certified from its config"
        )


def _flat_top(controller, design) -> dict:
    """``flat_top_rho`` (the level ``rho_in`` on which an ROA hybrid's relevance is 1) and
    ``flat_top_same_P`` (its V is the certificate's), for a controller with an ROA relevance;
    empty otherwise."""
    import numpy as np

    from leoc.policies import ROARelevance

    modules = controller.modules() if hasattr(controller, "modules") else ()
    module = next((m for m in modules if isinstance(m, ROARelevance)), None)
    if module is None:
        return {}
    matrix = module.lyapunov_matrix.detach().cpu().numpy()
    return {
        "flat_top_rho": float(module.rho_in),
        "flat_top_same_P": bool(np.allclose(matrix, design.P, rtol=LINEAR_PART_RTOL, atol=0.0)),
    }


def _roa_controllers(system, design, lqr: CertifiedLQR, runs: dict) -> dict:
    """The certified LQR (at the design's period, with the runs' squash) and every
    ``--controller`` run, by label."""
    from leoc.policies.hybrid import saturated_lqr

    controllers = {
        f"LQR (period {design.action_repeat})": saturated_lqr(system, design, lqr.saturation)
    }
    labels = run_labels(list(runs))
    for spec, controller in runs.items():
        controllers[labels[spec]] = controller
    return controllers


class _Certified(NamedTuple):
    """The LQR ``leoc roa`` certifies: its ``design`` (:class:`~leoc.control.LQRDesign`) and
    the ``certificate`` of its closed loop (:func:`~leoc.policies.hybrid.lqr_certificate`)."""

    design: Any
    certificate: Any


def _certify(args: argparse.Namespace, system, lqr: CertifiedLQR, runs: dict) -> _Certified:
    """Design the LQR ``lqr``, check that it is every run's linear part, and certify it."""
    from leoc.control import design_lqr
    from leoc.policies.hybrid import lqr_certificate

    design = design_lqr(system, method=lqr.method, action_repeat=lqr.action_repeat)  # type: ignore[arg-type]
    for spec, controller in runs.items():
        _check_linear_part(spec, controller, design, lqr)
    # The closed loop the runs' ROA hybrids are flat on (leoc.policies.roa_hybrid and the
    # DDPG hybrids' relevance certify it with this one function).
    certificate = lqr_certificate(
        system, design, lqr.saturation, samples=args.samples, seed=args.seed
    )
    return _Certified(design, certificate)


class _BoxCover(NamedTuple):
    """The basin box and the share of it the certified set covers (sampled)."""

    box: Any  # (S,) half-widths per state, in the state's units
    fraction: float
    stderr: float


def _box_cover(args: argparse.Namespace, system, certificate) -> _BoxCover:
    """``--box`` (default :func:`~leoc.evaluation.basins.default_basin_box`) and the share of it
    inside the certified set (:func:`~leoc.evaluation.basins.box_fraction`, seeded)."""
    import numpy as np

    from leoc.evaluation.basins import box_fraction, default_basin_box

    box = default_basin_box(system) if args.box is None else np.asarray(args.box, dtype=float)
    fraction, error = box_fraction(certificate, box, seed=args.seed)
    return _BoxCover(box, fraction, error)


def _measure_basins(
    args: argparse.Namespace, system, certified: _Certified, lqr: CertifiedLQR, runs: dict, box
) -> dict:
    """Per controller label: the controller, the share of ``--starts`` seeded starts in ``box``
    and of as many in the certified set that it holds, and an ROA hybrid's flat top."""
    from leoc.evaluation.basins import basin_starts, certified_set_check, empirical_basin

    starts = basin_starts(system, box, args.starts, seed=args.seed)
    basins = {}
    for label, controller in _roa_controllers(system, certified.design, lqr, runs).items():
        basin = empirical_basin(system, controller, starts, box=box)
        inside = certified_set_check(
            system, controller, certified.certificate, args.starts, args.seed
        )
        basins[label] = {
            "controller": controller,
            "box_held": basin.fraction,
            "certified_set_held": inside.fraction,
            **_flat_top(controller, certified.design),
        }
    return basins


def _roa_report(
    args: argparse.Namespace,
    system,
    lqr: CertifiedLQR,
    runs: dict,
    certified: _Certified,
    cover: _BoxCover,
    basins: dict,
) -> dict:
    """The results of ``leoc roa`` as printed by ``--json`` (the controllers left out)."""
    return {
        "system": args.system,
        "plant": dataclasses.asdict(system.rules.plant()),
        "action_repeat": certified.design.action_repeat,
        "lqr": {**lqr._asdict(), "from_runs": bool(runs)},
        "certificate": certified.certificate.summary(),
        "box": cover.box.tolist(),
        "box_fraction": cover.fraction,
        "box_fraction_stderr": cover.stderr,
        "basin_starts": args.starts,
        "basins": {
            label: {key: value for key, value in entry.items() if key != "controller"}
            for label, entry in basins.items()
        },
    }


def _plot_slices(args: argparse.Namespace, system, certificate, basins: dict, box) -> str:
    """Write the basins of every controller on the system's 2-D slice (:data:`ROA_SLICES`,
    ``--slice-points`` per axis) to ``--plot``; the path written."""
    import numpy as np

    from leoc.evaluation.basins import empirical_basin, slice_grid
    from leoc.evaluation.plots.basins import plot_basins

    dims = ROA_SLICES.get(args.system, (0, 1))
    # The slice box covers the certified ellipse too, so the plot shows its boundary.
    plot_box = np.maximum(box, ROA_PLOT_MARGIN * certificate.extent)
    grid = slice_grid(system, dims, plot_box, args.slice_points)
    slices = {
        label: empirical_basin(system, entry["controller"], grid, box=plot_box)
        for label, entry in basins.items()
    }
    return str(
        plot_basins(system, certificate, slices, dims, args.slice_points, args.plot, box=box)
    )


def _prove_controllers(
    args: argparse.Namespace, system, certified: _Certified, saturation: str, runs, box
):
    """Per run label: its proved region beside the LQR's
    (:func:`~leoc.evaluation.proved_regions.proved_region`); progress on stderr."""
    import sys

    from leoc.evaluation.proved_regions import proved_region

    proofs = {}
    labels = run_labels(list(runs))
    for spec, controller in runs.items():
        label = labels[spec]
        print(f"leoc roa: proving {label}'s own region ...", file=sys.stderr, flush=True)
        proofs[label] = proved_region(
            system,
            controller,
            certified.design,
            certified.certificate,
            box,
            saturation=saturation,
            lyapunov=args.lyapunov,
            samples=args.samples,
            seed=args.seed,
            max_seconds=args.proof_seconds,
            device=args.device,
        )
    return proofs


def _check_device(args: argparse.Namespace) -> None:
    """``--device``: a usable device, and only with ``--prove`` (one-line errors)."""
    if args.device == "cpu":
        return
    if not args.prove:
        raise ValueError(f"--device: expected only with --prove, found --device {args.device}")
    from leoc.control.proof import check_device

    try:
        check_device(args.device)
    except ValueError as error:
        raise ValueError(f"--{error}") from None


def run(args: argparse.Namespace) -> int:
    import time

    from leoc.cli._gym import refuse_gym_roa

    refuse_gym_roa(list(args.controller or []))
    import torch

    from leoc.experiments.controllers import trained_under

    torch.set_num_threads(1)
    started = time.perf_counter()
    if args.prove and not args.controller:
        raise ValueError(
            "--prove: expected --controller RUN_DIR ... (the LQR's own region is always proved), "
            "found none"
        )
    _check_device(args)
    system = roa_plant(args)
    runs = {spec: load_controller(spec, args.system) for spec in args.controller or []}
    lqr = certified_lqr_choice(args, runs)
    certified = _certify(args, system, lqr, runs)
    cover = _box_cover(args, system, certified.certificate)
    basins = _measure_basins(args, system, certified, lqr, runs, cover.box)
    report = _roa_report(args, system, lqr, runs, certified, cover, basins)
    report["trained_under"] = trained_under(list(runs))  # certified on the nominal plant
    if args.prove:
        report["proofs"] = _prove_controllers(
            args, system, certified, lqr.saturation, runs, cover.box
        )
    if args.plot:
        report["plot"] = _plot_slices(args, system, certified.certificate, basins, cover.box)
    report["seconds"] = time.perf_counter() - started
    if args.json:
        print(json.dumps(report, indent=1))
        return 0
    _print_roa(system, certified.certificate, report)
    return 0


def _print_roa(system, certificate, report: dict) -> None:
    names = ", ".join(system.state_names)
    lqr = report["lqr"]
    whose = "the runs' own: " if lqr["from_runs"] else ""
    print(
        f"Region of attraction of the LQR ({whose}{lqr['method']} design, {lqr['saturation']} "
        f"squash) on {report['system']} (control period {report['action_repeat']} step(s), "
        f"dt = {system.dt} s"
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
        flat = entry.get("flat_top_rho")
        top = (
            ""
            if flat is None
            else f" (ROA relevance: r = 1 on V <= {flat:.6g}"
            f"{'' if entry['flat_top_same_P'] else ', another V'})"
        )
        print(
            f"  {label}: {entry['box_held']:.1%} of the box; {entry['certified_set_held']:.1%} of "
            f"the certified set{top}"
        )
    if "proofs" in report:
        from leoc.evaluation.proved_regions import describe_proved_region

        print("proved regions of the controllers' own closed loops (V centred on each one's x*):")
        for label, entry in report["proofs"].items():
            for line in describe_proved_region(system, label, entry):
                print(line)
    if "plot" in report:
        print(f"figure written to {report['plot']}")
    print(f"({report['seconds']:.1f} s)")
