"""The ``leoc`` command: LQR design, simulation, training, the paper's experiments and plots.

Run ``leoc --help`` or ``leoc COMMAND --help``.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

# Exit statuses of an interrupted command: 128 + the signal number, as a shell reports it.
EXIT_SIGINT = 128 + signal.SIGINT
EXIT_SIGTERM = 128 + signal.SIGTERM
ALGO_CHOICES = ("pilco", "ddpg", "td3")
DEFAULT_RUNS_DIR = Path("runs")


def _print_matrix(name: str, matrix: np.ndarray) -> None:
    text = np.array2string(np.atleast_2d(matrix), precision=6, suppress_small=True)
    print(f"{name} =\n{text}")


def cmd_lqr(args: argparse.Namespace) -> int:
    from leoc.control import design_lqr
    from leoc.experiments.linear import design_summary
    from leoc.systems import make_system

    system = make_system(args.system)
    design = design_lqr(system, Q=args.q, R=args.r, method=args.method)
    if args.json:
        print(json.dumps(design_summary(design), indent=1))
        return 0
    print(f"LQR design for {args.system} ({args.method}), dt = {system.dt} s")
    print(f"state: {', '.join(system.state_names)}")
    observed = system.observation.labels(system.state_names)
    print(f"observation: {', '.join(observed)}")
    _print_matrix("A_d", design.A_d)
    _print_matrix("B_d", design.B_d)
    _print_matrix("Q", design.Q)
    _print_matrix("R", design.R)
    _print_matrix("K (u = u_eq - K (x - a))", design.K)
    _print_matrix("W (G(o) = W o + b)", design.W)
    _print_matrix("b", design.b)
    eig = ", ".join(f"{z:.4f}" for z in design.closed_loop_eigenvalues)
    print(f"closed-loop eigenvalues: {eig}")
    print(f"spectral radius: {design.spectral_radius:.6f} (stable: {design.spectral_radius < 1})")
    margins = design.margins
    low, high = margins.gain_interval
    print(
        f"gain margin: {margins.gain_margin:.4f} (lower margin; loop stable for gain factors in "
        f"[{low:.4f}, {high:.4f}])"
    )
    print(
        f"phase margin: {margins.phase_margin:.2f} deg at "
        f"{margins.gain_crossover_frequency:.3f} rad/s"
    )
    return 0


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
    if spec == "linear":
        if method is not None:
            chosen = dataclasses.replace(chosen, lqr_method=method)
        return chosen.linear_controller(chosen.system(system_name), action_repeat)
    from leoc.experiments.controllers import load_trained_controller

    return load_trained_controller(Path(spec), system=system_name)


def cmd_simulate(args: argparse.Namespace) -> int:
    from leoc.evaluation.plots import plot_responses
    from leoc.evaluation.rollout import control_period, response_test
    from leoc.experiments.variants import get_variant

    variant = get_variant(args.variant)
    system = variant.system(args.system)
    controller = load_controller(
        args.controller, args.system, args.method, args.action_repeat, args.variant
    )
    if args.steps is None:
        args.steps = variant.steps_for(args.system)
    if args.band is not None and args.metrics == "authors":
        raise SystemExit("leoc simulate: error: --band: the authors' metrics fix the band (pi/180)")
    result = response_test(
        system, controller, args.test, steps=args.steps, band=args.band, metric_set=args.metrics
    )
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
    period = control_period(controller)
    if args.json:
        print(
            json.dumps(
                {
                    "system": args.system,
                    "controller": args.controller,
                    "test": args.test,
                    "variant": args.variant,
                    "metrics_set": args.metrics,
                    "action_repeat": period,
                    "metrics": metrics._asdict(),
                    "deviation": result.deviation.tolist(),
                    "total_reward": result.trajectory.total_reward,
                }
            )
        )
        return 0
    print(
        f"{args.test} response of {args.controller} on {args.system} ({args.steps} steps, "
        f"control period {period} step{'s' if period > 1 else ''}; variant {args.variant}, "
        f"{args.metrics} metrics)"
    )
    print(f"  steady-state error: {metrics.steady_state_error:.6g} {unit}")
    print(f"  overshoot:          {metrics.overshoot:.6g} {unit}")
    print(f"  peak deviation:     {metrics.peak_deviation:.6g} {unit}")
    print(f"  settling time:      {settling} (band {band})")
    print(f"  terminated:         {'yes' if metrics.terminated else 'no'}")
    print(f"  return:             {result.trajectory.total_reward:.4f}")
    if args.plot:
        label = "linear" if args.controller == "linear" else Path(args.controller).name
        record = {
            "deviation": result.deviation,
            "terminated": metrics.terminated,
            "settled": metrics.settled,
        }
        path = plot_responses({args.system: {args.test: {label: [record]}}}, args.plot)
        print(f"figure written to {path}")
    return 0


def cmd_train(args: argparse.Namespace) -> int:
    kind = "hybrid" if args.hybrid else "baseline"
    run_dir = args.out or DEFAULT_RUNS_DIR / f"{args.system}_{args.algo}_{kind}_seed{args.seed}"
    if args.algo == "pilco":
        from leoc.pilco.train import train_pilco

        result = train_pilco(
            args.system,
            hybrid=args.hybrid,
            seed=args.seed,
            run_dir=run_dir,
            iterations=args.iterations,
            progress=not args.quiet,
        )
    else:
        from leoc.ddpg.train import train_ddpg

        result = train_ddpg(
            args.system,
            algo=args.algo,
            hybrid=args.hybrid,
            seed=args.seed,
            run_dir=run_dir,
            total_steps=args.steps,
            progress=not args.quiet,
        )
    print(f"run folder: {result.run_dir}")
    return 0


def cmd_reproduce(args: argparse.Namespace) -> int:
    from leoc.experiments.reproduce import reproduce

    path = reproduce(
        args.out,
        profile_name=args.profile,
        jobs=args.jobs,
        seeds=args.seeds,
        systems=args.systems,
        controllers=args.controllers,
        backend=args.backend,
        address=args.address,
    )
    print(path.read_text())
    print(f"report written to {path}")
    return 0


def cmd_plot(args: argparse.Namespace) -> int:
    from leoc.experiments.report import write_report

    path = write_report(args.run_dir)
    print(f"figures and report regenerated: {path}")
    return 0


def cmd_publish(args: argparse.Namespace) -> int:
    from leoc.experiments.publish import publish

    path = publish(args.run_dir, args.dest)
    print(f"numbers copied and report written: {path}")
    return 0


ROA_SLICES = {"pendulum": (0, 1), "cartpole": (2, 3), "mountaincar": (0, 1)}
"""2-D slice of each system's basin plot: theta vs theta_dot, or x vs x_dot."""
ROA_PLOT_MARGIN = 1.25
"""The plot's slice box reaches at least this factor times the certified set's extent."""


def _roa_controllers(args: argparse.Namespace, system, design) -> dict:
    """The LQR (at the design's period) and every ``--controller`` run folder, by label."""
    from leoc.control import lqr_closed_loop

    controllers = {f"LQR (period {design.action_repeat})": lqr_closed_loop(design)}
    for spec in args.controller or []:
        controllers[Path(spec).name] = load_controller(spec, args.system)
    return controllers


def cmd_roa(args: argparse.Namespace) -> int:
    import time

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
    from leoc.systems import make_system

    torch.set_num_threads(1)
    started = time.perf_counter()
    system = make_system(args.system)
    design = design_lqr(system, action_repeat=args.action_repeat)
    certificate = certify_lqr(system, design, samples=args.samples, seed=args.seed)
    box = default_basin_box(system) if args.box is None else np.asarray(args.box, dtype=float)
    fraction, error = box_fraction(certificate, box, seed=args.seed)
    starts = basin_starts(system, box, args.starts, seed=args.seed)
    basins = {}
    for label, controller in _roa_controllers(args, system, design).items():
        basin = empirical_basin(system, controller, starts, box=box)
        inside = certified_set_check(system, controller, certificate, args.starts, args.seed)
        basins[label] = {
            "controller": controller,
            "box_held": basin.fraction,
            "certified_set_held": inside.fraction,
        }
    report = {
        "system": args.system,
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
            plot_basins(system, certificate, slices, dims, args.slice_points, args.plot)
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
        f"{report['action_repeat']} step(s), dt = {system.dt} s); state: {names}"
    )
    print("V(x) = z^T P z, z = x - a (angles wrapped); certified: V(F(x)) < V(x) on 0 < V <= rho")
    _print_matrix("P", certificate.P)
    if not certificate.certified:
        print(
            f"rho = 0: no certified set (linear decrease {certificate.linear_decrease}, largest "
            f"eigenvalue of A_cl^T P A_cl - P = {certificate.linear_decrease_eig:.4g})"
        )
    else:
        print(
            f"rho = {certificate.rho:.6g}"
            + (" (capped by the search box)" if certificate.capped else "")
        )
        extent = ", ".join(
            f"{name} +/- {width:.4g}"
            for name, width in zip(system.state_names, certificate.extent, strict=True)
        )
        print(f"extent: {extent}")
        print(
            f"samples: {certificate.samples} uniform in the set in the final clean round "
            f"({certificate.rounds} rounds); with confidence {certificate.confidence:g} the "
            f"violating volume fraction is < {certificate.violation_bound:.3g}"
        )
        if certificate.grid is not None:
            grid = certificate.grid
            print(
                f"dense grid: {grid.nodes} nodes ({grid.points_per_axis} per axis) all decrease; "
                f"with the local Lipschitz estimate (max {grid.lipschitz:.4g}) the decrease is "
                f"proved on {grid.core_level:.4g} < V < {grid.proved_level:.4g}"
            )
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


class OneLineParser(argparse.ArgumentParser):
    """An argument parser whose errors are one line on stderr (exit status 2)."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def positive_int(text: str) -> int:
    """argparse type: an integer >= 1."""
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, found {value}")
    return value


def non_negative_int(text: str) -> int:
    """argparse type: an integer >= 0."""
    value = int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a non-negative integer, found {value}")
    return value


def positive_float(text: str) -> float:
    """argparse type: a finite number > 0."""
    value = float(text)
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"expected a positive number, found {text}")
    return value


def system_choices() -> tuple[str, ...]:
    """The registered system names (the CLI's one place that resolves names)."""
    from leoc.systems import system_names

    return system_names()


def build_parser() -> argparse.ArgumentParser:
    from leoc.systems import SYSTEM_NAMES as paper_systems

    systems = system_choices()
    parser = OneLineParser(
        prog="leoc",
        description="LEOC hybrid controllers: LQR near the operating point, a learned policy "
        "elsewhere (Zhang & Capel, L4DC 2021).",
    )
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    lqr = commands.add_parser("lqr", help="design the LQR of a system and print it")
    lqr.add_argument("system", choices=systems)
    lqr.add_argument(
        "--method",
        choices=("discrete", "continuous", "authors"),
        default="discrete",
        help="discrete: dlqr on the autodiff linearisation (default); continuous: lqr on the "
        "paper's analytic model; authors: nrjc/LEOC's lqr on their models (R = 1) times u_max",
    )
    lqr.add_argument("--q", type=float, nargs="+", help="diagonal of Q (default per system)")
    lqr.add_argument("--r", type=float, nargs="+", help="diagonal of R (default 1)")
    lqr.add_argument("--json", action="store_true", help="print the design as JSON")
    lqr.set_defaults(func=cmd_lqr)

    simulate = commands.add_parser(
        "simulate", help="impulse or step response of a controller from the operating point"
    )
    simulate.add_argument("system", choices=systems)
    simulate.add_argument(
        "--controller",
        default="linear",
        help="'linear' (the LQR) or a run folder written by 'leoc train' or printed by "
        "'leoc reproduce' (default: linear); a trained controller runs at its trained period",
    )
    simulate.add_argument(
        "--action-repeat",
        type=positive_int,
        default=1,
        help="control period of the linear controller in simulator steps (its LQR is designed "
        "for it; PILCO's is 3); default 1",
    )
    simulate.add_argument(
        "--band",
        type=positive_float,
        help="absolute settling band (deg or m); default 2%% of the peak error",
    )
    simulate.add_argument("--test", choices=("impulse", "step"), default="impulse")
    simulate.add_argument(
        "--steps",
        type=positive_int,
        help="episode length (default: the variant's, 200; the authors' cart-pole record: 400)",
    )
    simulate.add_argument(
        "--method",
        choices=("discrete", "continuous", "authors"),
        help="LQR design of the linear controller (default: the variant's; leoc: discrete)",
    )
    simulate.add_argument(
        "--variant",
        choices=("leoc", "authors"),
        default="leoc",
        help="implementation: leoc's defaults, or the authors' (nrjc/LEOC: their LQR scaled by "
        "u_max with a sin squash, their env rules); default leoc",
    )
    simulate.add_argument(
        "--metrics",
        choices=("leoc", "authors"),
        default="leoc",
        help="metric set: leoc's (final-window mean, band 2%% of the peak) or the authors' "
        "(arcsin(sin theta), last sample, band +/- pi/180); default leoc",
    )
    simulate.add_argument("--plot", type=Path, help="write a PNG of the response here")
    simulate.add_argument(
        "--json", action="store_true", help="print the metrics and e(t) as JSON instead"
    )
    simulate.set_defaults(func=cmd_simulate)

    roa = commands.add_parser(
        "roa",
        help="certify the LQR's region of attraction and measure empirical basins",
        description="Certify the largest sublevel set of V = z^T P z (P from the LQR design) on "
        "which V decreases along the nonlinear, saturated, held closed loop (sampling after "
        "Najafi et al. 2016; dense grid and Lipschitz margin for 2-D states), and simulate "
        "seeded starts in a box for the LQR and each --controller.",
    )
    roa.add_argument("system", choices=systems)
    roa.add_argument(
        "--controller", nargs="+", help="run folders written by 'leoc train' (basins of each)"
    )
    roa.add_argument(
        "--action-repeat",
        type=positive_int,
        default=1,
        help="control period of the LQR (default 1)",
    )
    roa.add_argument(
        "--samples",
        type=positive_int,
        default=100_000,
        help="samples per certificate round (100000)",
    )
    roa.add_argument(
        "--starts", type=positive_int, default=2000, help="basin starts (default 2000)"
    )
    roa.add_argument(
        "--box", type=positive_float, nargs="+", help="basin box half-widths per state"
    )
    roa.add_argument("--seed", type=non_negative_int, default=0)
    roa.add_argument(
        "--slice-points",
        type=positive_int,
        default=41,
        help="grid points per axis of the plot slice",
    )
    roa.add_argument("--plot", type=Path, help="write a PNG of the basin slices here")
    roa.add_argument("--json", action="store_true", help="print the results as JSON")
    roa.set_defaults(func=cmd_roa)

    train = commands.add_parser("train", help="train a baseline or hybrid controller")
    train.add_argument("system", choices=systems)
    train.add_argument("--algo", choices=ALGO_CHOICES, required=True)
    train.add_argument("--hybrid", action="store_true", help="train the LEOC hybrid")
    train.add_argument("--seed", type=non_negative_int, default=0)
    train.add_argument("--out", type=Path, help="run folder (default runs/SYSTEM_ALGO_KIND_seedN)")
    train.add_argument(
        "--iterations", type=positive_int, help="PILCO iterations (default per system)"
    )
    train.add_argument(
        "--steps", type=positive_int, help="DDPG/TD3 environment steps (default per system)"
    )
    train.add_argument("--quiet", action="store_true", help="no progress output")
    train.set_defaults(func=cmd_train)

    from leoc.experiments.profiles import CONTROLLERS, DEFAULT_CONTROLLERS, PROFILE_NAMES

    reproduce = commands.add_parser(
        "reproduce",
        help="train and evaluate every controller of the paper and write the report",
        description="Train (or design) linear, DDPG baseline/hybrid and PILCO baseline/hybrid "
        "controllers on the three systems over seeds, in parallel workers, then evaluate "
        "responses, robustness and relevance and write report.md with CSV/JSON/PNG. Finished "
        "runs are kept: rerunning the same command resumes.",
    )
    reproduce.add_argument(
        "--profile",
        choices=PROFILE_NAMES,
        default="quick",
        help="quick (default: 1 seed, reduced budgets), paper (paper budgets, 3 seeds) or "
        "smoke (a tiny pipeline check)",
    )
    reproduce.add_argument("--out", help="output folder (default runs/reproduce-PROFILE)")
    reproduce.add_argument(
        "--jobs",
        type=positive_int,
        help="runs at a time (default: the CPU count; on Ray, as many as the cluster's CPUs)",
    )
    reproduce.add_argument(
        "--backend",
        choices=("local", "ray"),
        default="local",
        help="local: worker processes on this machine (default); ray: one Ray task per run "
        "(needs pip install 'leoc[ray]')",
    )
    reproduce.add_argument(
        "--address",
        help="Ray only: the cluster to join ('auto' inside a cluster started with 'ray start', "
        "or HEAD_IP:6379); default: a private Ray instance on this machine",
    )
    reproduce.add_argument(
        "--seeds", type=positive_int, help="number of seeds (default per profile)"
    )
    reproduce.add_argument("--systems", nargs="+", choices=systems, default=list(paper_systems))
    reproduce.add_argument(
        "--controllers",
        nargs="+",
        choices=CONTROLLERS,
        default=list(DEFAULT_CONTROLLERS),
        help="controllers to run (default: the two linear references and the paper's four; "
        "add ddpg_hybrid_roa / pilco_hybrid_roa for the ROA-relevance hybrids)",
    )
    reproduce.set_defaults(func=cmd_reproduce)

    plot = commands.add_parser(
        "plot", help="regenerate the figures and report of a reproduce folder from saved numbers"
    )
    plot.add_argument("run_dir", type=Path)
    plot.set_defaults(func=cmd_plot)

    publish = commands.add_parser(
        "publish",
        help="copy a reproduce folder's numbers (not its weights) to DEST and write the report "
        "there (for results kept in a repository)",
    )
    publish.add_argument("run_dir", type=Path)
    publish.add_argument("dest", type=Path)
    publish.set_defaults(func=cmd_publish)
    return parser


class Terminated(Exception):
    """Raised in the main process by SIGTERM, so it stops as cleanly as on Ctrl-C."""


def _raise_terminated(signum: int, frame: object) -> None:
    raise Terminated()


RESUMABLE_COMMANDS = ("reproduce", "train")


def _interrupted(args: argparse.Namespace, code: int) -> int:
    if args.command in RESUMABLE_COMMANDS:
        print(
            f"leoc {args.command}: interrupted; finished runs and checkpoints are kept, run the "
            "same command again to resume",
            file=sys.stderr,
        )
    else:
        print(f"leoc {args.command}: interrupted", file=sys.stderr)
    return code


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command == "reproduce" and args.out is None:
        args.out = str(DEFAULT_RUNS_DIR / f"reproduce-{args.profile}")
    previous = signal.signal(signal.SIGTERM, _raise_terminated)
    try:
        return int(args.func(args))
    except (ValueError, FileNotFoundError) as error:
        print(f"leoc {args.command}: error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return _interrupted(args, EXIT_SIGINT)
    except Terminated:
        return _interrupted(args, EXIT_SIGTERM)
    finally:
        signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":
    sys.exit(main())
