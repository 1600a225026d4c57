"""Time of a trained controller's own proved region (``leoc roa --controller RUN --prove``).

For each run folder given: the equilibrium search, then each candidate V's sampled estimate and
proof (:func:`leoc.control.certify_controller`), with the proved level, the boxes evaluated,
boxes per second of the proof and what limited it. Run on one torch thread, as ``leoc roa``
does (the figure for 2 cores is the same per controller; two controllers run side by side).

Usage::

    python benchmarks/bench_controller_proof.py RUN_DIR [RUN_DIR ...] [--seconds 480]
        [--device cpu|cuda] [--threads 1]

``--device cuda`` evaluates the boxes on a GPU (``leoc roa --prove --device cuda``); compare
with ``--device cpu`` on the same machine (``--threads`` CPU threads) for the speed-up.

Target (issue 42): every paper system's trained controller (MLP 400x300, RBF 10-50 features)
certified in under 10 minutes on 2 cores. Measured on this project's 2-core machine
(2026-11-27): pendulum TD3/DDPG/SAC hybrids and baselines 18-25 s each with both V.
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
from leoc.systems.rollout import control_period

TARGET_SECONDS = 600.0


def _row(spec: str, seconds: float, device: str) -> str:
    system = trained_plant(spec)
    controller = load_trained_controller(spec, system=trained_system(spec))
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
        f"| {spec} | {device} | {proved.lyapunov} | {'; '.join(cells)} | {total:.1f} | {verdict} |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", help="run folders written by leoc train")
    parser.add_argument("--seconds", type=float, default=480.0, help="proof budget per run")
    parser.add_argument("--device", default="cpu", help="cpu (default) or cuda[:N]")
    parser.add_argument("--threads", type=int, default=1, help="CPU threads (default 1)")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    print(f"torch {torch.__version__}, {args.threads} CPU thread(s), device {args.device}")
    print("| run | device | V kept | per candidate V | seconds | under 10 min |")
    print("|---|---|---|---|---|---|")
    for spec in args.runs:
        print(_row(spec, args.seconds, args.device), flush=True)


if __name__ == "__main__":
    main()
