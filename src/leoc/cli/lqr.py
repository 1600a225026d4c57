"""``leoc lqr``: design the LQR of a system and print it."""

from __future__ import annotations

import argparse
import json
from typing import Any

from leoc.cli._args import SYSTEM_HELP, positive_int, system_name
from leoc.names import GYM_PREFIX, gym_env_id
from leoc.names import LQR_METHODS as METHODS


def add_parser(commands: Any) -> None:
    """Add the ``lqr`` command to the subparsers ``commands``."""
    lqr = commands.add_parser(
        "lqr",
        help="design the LQR of a system and print it",
        description="Design the LQR of a system about its operating point and print A_d, B_d, "
        "Q, R, the gain K, the observation-space form G(o) = W o + b, the closed-loop "
        "eigenvalues and the stability margins.",
    )
    lqr.add_argument(
        "system",
        type=lqr_system,
        metavar="SYSTEM",
        help=f"{SYSTEM_HELP}; or {GYM_PREFIX}ENV_ID, a gymnasium env with a default operating "
        "point (MuJoCo's rest state): the discrete LQR of its own step by central differences",
    )
    lqr.add_argument(
        "--method",
        choices=METHODS,
        default="discrete",
        help="discrete: dlqr on the autodiff linearisation (default); continuous: lqr on the "
        "paper's analytic model; authors: nrjc/LEOC's lqr on their models (R = 1) times u_max",
    )
    lqr.add_argument("--q", type=float, nargs="+", help="diagonal of Q (default per system)")
    lqr.add_argument("--r", type=float, nargs="+", help="diagonal of R (default 1)")
    lqr.add_argument(
        "--action-repeat",
        type=positive_int,
        default=1,
        help="control period in simulator steps: design for the map that holds each action "
        "this many steps (PILCO's LQR: 3 on the pendulum and cart-pole); A_d, B_d, the "
        "eigenvalues and the margins are those of that map, sample time N dt (default 1)",
    )
    lqr.add_argument("--json", action="store_true", help="print the design as JSON")
    lqr.set_defaults(run=run)


def lqr_system(text: str) -> str:
    """argparse type of ``leoc lqr``'s SYSTEM: a system name or ``gym:ENV_ID``."""
    if text.startswith(GYM_PREFIX):
        try:
            gym_env_id(text)
        except ValueError as error:
            raise argparse.ArgumentTypeError(str(error)) from None
        return text
    return system_name(text)


def print_matrix(name: str, matrix: Any) -> None:
    """Print ``name =`` and the matrix, 6 digits."""
    import numpy as np

    text = np.array2string(np.atleast_2d(matrix), precision=6, suppress_small=True)
    print(f"{name} =\n{text}")


def run(args: argparse.Namespace) -> int:
    if gym_env_id(args.system) is not None:
        return run_gym_lqr(args)
    from leoc.control import design_lqr
    from leoc.experiments.linear import design_summary
    from leoc.systems import make_system

    system = make_system(args.system)
    design = design_lqr(
        system, Q=args.q, R=args.r, method=args.method, action_repeat=args.action_repeat
    )
    period = design.action_repeat * system.dt
    if args.json:
        summary = design_summary(design)
        summary.update(action_repeat=design.action_repeat, dt=system.dt, control_period=period)
        print(json.dumps(summary, indent=1))
        return 0
    print(
        f"LQR design for {args.system} ({args.method}), dt = {system.dt} s, control period "
        f"{design.action_repeat} step(s) = {period:g} s (action held)"
    )
    print(f"state: {', '.join(system.state_names)}")
    observed = system.observation.labels(system.state_names)
    print(f"observation: {', '.join(observed)}")
    print_matrix("A_d", design.A_d)
    print_matrix("B_d", design.B_d)
    print_matrix("Q", design.Q)
    print_matrix("R", design.R)
    print_matrix("K (u = u_eq - K (x - a))", design.K)
    print_matrix("W (G(o) = W o + b)", design.W)
    print_matrix("b", design.b)
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


def run_gym_lqr(args: argparse.Namespace) -> int:
    """``leoc lqr gym:ENV_ID``: the discrete LQR of the env's own step (central differences,
    :func:`leoc.sb3.gym_plant`) about its default operating point, with the error bounds."""
    import numpy as np

    from leoc.gym_adapter import linearise_env
    from leoc.sb3.gym import gym_plant, make_gym_env

    if args.method != "discrete" or args.action_repeat != 1:
        raise ValueError(
            f"--method, --action-repeat: expected discrete and 1 for a gymnasium env (the "
            f"discrete LQR of its own step), found {args.method} and {args.action_repeat}"
        )
    env_id = str(gym_env_id(args.system))
    env = make_gym_env(env_id)
    plant = gym_plant(env, env_id, None, args.q, args.r)
    lin, lqr = linearise_env(env, plant.state, plant.action), plant.lqr  # plant's, again
    dt = float(env.unwrapped.dt)
    env.close()
    eigenvalues = lqr.closed_loop_eigenvalues
    summary = {
        "system": args.system,
        "dt": dt,
        "state": lqr.state.tolist(),
        "action": lqr.action.tolist(),
        "A_d": lin.A_d.tolist(),
        "B_d": lin.B_d.tolist(),
        "error_A": float(np.max(lin.error_A)),
        "error_B": float(np.max(lin.error_B)),
        "Q": lqr.Q.tolist(),
        "R": lqr.R.tolist(),
        "K": lqr.K.tolist(),
        "W": plant.gain.tolist(),
        "b": plant.bias.tolist(),
        "closed_loop_eigenvalues": [[z.real, z.imag] for z in eigenvalues],
        "spectral_radius": float(np.max(np.abs(eigenvalues))),
        "observation_jacobian_error": plant.jacobian_error,
        "observation_error": plant.observation_error,
    }
    if args.json:
        print(json.dumps(summary, indent=1))
        return 0
    _print_gym_lqr(summary, plant)
    return 0


def _print_gym_lqr(summary: dict[str, Any], plant: Any) -> None:
    """The text of ``leoc lqr gym:ENV_ID``."""
    print(
        f"LQR design for {summary['system']} (discrete, central differences of the env's own "
        f"step), dt = {summary['dt']} s; operating state {summary['state']}, action "
        f"{summary['action']}"
    )
    for name in ("A_d", "B_d", "Q", "R", "K"):
        print_matrix(name + (" (u = u_eq - K (x - x_eq))" if name == "K" else ""), summary[name])
    print(f"largest error bound of A_d: {summary['error_A']:.3g}, of B_d: {summary['error_B']:.3g}")
    print_matrix("W (G(o) = W o + b, on the observation)", plant.gain)
    print_matrix("b", plant.bias)
    eigenvalues = plant.lqr.closed_loop_eigenvalues
    print(f"closed-loop eigenvalues: {', '.join(f'{z:.4f}' for z in eigenvalues)}")
    radius = summary["spectral_radius"]
    print(f"spectral radius: {radius:.6f} (stable: {radius < 1})")
    print(
        f"observation map: Jacobian error {plant.jacobian_error:.3g}, observation error "
        f"{plant.observation_error:.3g} (relative, at the env's default starts)"
    )
