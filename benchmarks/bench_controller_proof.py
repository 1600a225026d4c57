"""Time of a trained controller's own proved region (``leoc roa --controller RUN --prove``).

For each run folder given: the equilibrium search, then each candidate V's sampled estimate and
proof (:func:`leoc.control.certify_controller`), with the proved level, the boxes evaluated,
boxes per second of the proof and what limited it. Run on one torch thread, as ``leoc roa``
does (the figure for 2 cores is the same per controller; two controllers run side by side).

Usage::

    python benchmarks/bench_controller_proof.py RUN_DIR|seeded:SYSTEM [...] [--seconds 480]
        [--device cpu|cuda] [--threads 1]

``seeded:SYSTEM`` proves the paper-relevance hybrid of SYSTEM's LQR and a seeded, untrained
400x300 actor (leoc's DDPG/TD3 size) instead of a trained run; ``seeded-roa:SYSTEM`` the ROA
hybrid of the same (flat on its LQR's proved level). ``--no-flat-region`` hides the
controllers' flat regions from the proof (``leoc.control.proof``, **Flat regions**), for the
comparison.

``--device cuda`` evaluates the boxes on a GPU (``leoc roa --prove --device cuda``); compare
with ``--device cpu`` on the same machine (``--threads`` CPU threads) for the speed-up.

Target (issue 42): every paper system's trained controller (MLP 400x300, RBF 10-50 features)
certified in under 10 minutes on 2 cores. Measured on this project's 2-core machine
(2026-11-27): pendulum TD3/DDPG/SAC hybrids and baselines 18-25 s each with both V. On an
NVIDIA H200 machine (2026-11-28; GPU against its 16 CPU threads): a partly trained pendulum TD3
hybrid 6.2 s against 8.2 s; ``seeded:mountaincar`` 13.4 s against 9.7 s; ``seeded:cartpole``
with a 90 s budget reaches the 3 million box budget in 34 s (rho 3.52, own V) against rho 0.27
in 93 s (docs/user_guide/roa.md, "On a GPU"). Flat regions (2026-12-07, this machine, one
busy core, ``seeded-roa:cartpole --seconds 120``, about 60 s per V): the Riccati V proves rho
14.29 (214 016 boxes, 3565 boxes/s) with them and 5.41 (144 384 boxes, 2402 boxes/s) with
``--no-flat-region``; the flat top is at 17.96.
"""

from __future__ import annotations

import argparse
import time

import torch

from leoc.control import certify_controller, design_lqr
from leoc.experiments.controllers import (
    load_trained_controller,
    trained_plant,
    trained_system,
)
from leoc.policies import HybridDesign, HybridSpec, build_hybrid, roa_hybrid
from leoc.policies.mlp import MLPActor
from leoc.systems import make_system
from leoc.systems.rollout import control_period

TARGET_SECONDS = 600.0


def seeded_hybrid(system, design):
    """The paper-relevance hybrid of ``design`` and a seeded 400x300 actor (float64, eval)."""
    limit = float(system.action_limit)
    actor = MLPActor(
        system.obs_dim,
        system.action_dim,
        (400, 300),
        action_limit=limit,
        generator=torch.Generator().manual_seed(0),
    )
    resolved = HybridDesign(design.W, design.b, system.operating_obs, {})
    spec = HybridSpec(r_min=None, relevance_power=1.0, lambda_init=1.0)
    hybrid = build_hybrid(spec, resolved, actor, action_limit=limit, saturation="clip")
    return hybrid.double().eval()


def seeded_roa_hybrid(system, design):
    """The ROA hybrid of ``design`` (flat on its LQR's proved level) and the same seeded actor."""
    actor = seeded_hybrid(system, design).nonlinear
    return roa_hybrid(system, design, actor, learn_width=False).double().eval()


def _plant_and_controller(spec: str):
    kind, _, name = spec.partition(":")
    if kind in ("seeded", "seeded-roa"):
        system = make_system(name)
        build = seeded_hybrid if kind == "seeded" else seeded_roa_hybrid
        return system, build(system, design_lqr(system))
    system = trained_plant(spec)
    return system, load_trained_controller(spec, system=trained_system(spec))


def _row(spec: str, seconds: float, device: str, flat_regions: bool = True) -> str:
    system, controller = _plant_and_controller(spec)
    if not flat_regions:
        controller.flat_region = lambda *args, **kwargs: None
    design = design_lqr(system, action_repeat=control_period(controller))
    started = time.perf_counter()
    proved = certify_controller(system, controller, design, max_seconds=seconds, device=device)
    total = time.perf_counter() - started
    cells = []
    for name, certificate in proved.candidates.items():
        proof = certificate.proof
        rate = proof.boxes / proof.seconds if proof.seconds > 0 else float("nan")
        cells.append(
            f"{name}: rho {certificate.rho:.4g}, {proof.boxes} boxes, {rate:.0f} boxes/s, "
            f"{proof.limited_by}"
        )
    verdict = "yes" if total < TARGET_SECONDS else "NO"
    return (
        f"| {spec}{'' if flat_regions else ' (no flat region)'} | {device} | {proved.lyapunov} "
        f"| {'; '.join(cells)} | {total:.1f} | {verdict} |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", help="run folders written by leoc train")
    parser.add_argument("--seconds", type=float, default=480.0, help="proof budget per run")
    parser.add_argument("--device", default="cpu", help="cpu (default) or cuda[:N]")
    parser.add_argument("--threads", type=int, default=1, help="CPU threads (default 1)")
    parser.add_argument(
        "--no-flat-region", action="store_true", help="hide the controllers' flat regions"
    )
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    print(f"torch {torch.__version__}, {args.threads} CPU thread(s), device {args.device}")
    print("| run | device | V kept | per candidate V | seconds | under 10 min |")
    print("|---|---|---|---|---|---|")
    for spec in args.runs:
        print(_row(spec, args.seconds, args.device, not args.no_flat_region), flush=True)


if __name__ == "__main__":
    main()
