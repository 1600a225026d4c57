"""Time of the proved region of attraction (``leoc roa``'s certificate) per system.

For each system: the LQR design, the sampled estimate (the proof's target) and the proof
(:func:`leoc.control.proof.prove_level`), each timed on its own, with the proved and sampled
levels, the boxes evaluated and what limited the proof. Run on one torch thread, as
``leoc roa`` does.

Usage::

    python benchmarks/bench_roa_proof.py [--systems pendulum cartpole mountaincar acrobot]

Targets (issue 21): under 60 s per paper system for the whole ``leoc roa`` on 2 cores;
the acrobot under 10 minutes or an explicit "not proved".
"""

from __future__ import annotations

import argparse
import time

import torch

from leoc.control import certify_lqr, design_lqr, lqr_closed_loop
from leoc.control.proof import prove_level
from leoc.systems import make_system

PAPER_TARGET_SECONDS = 60.0
ACROBOT_TARGET_SECONDS = 600.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--systems", nargs="+", default=["pendulum", "cartpole", "mountaincar", "acrobot"]
    )
    args = parser.parse_args()
    torch.set_num_threads(1)
    print(
        "| system | sampled rho | sampling s | proved rho | proved / sampled | proof s | boxes "
        "| limited by | target s |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for name in args.systems:
        system = make_system(name)
        design = design_lqr(system)
        started = time.perf_counter()
        sampled = certify_lqr(system, design, prove=False)
        sampling = time.perf_counter() - started
        proof = prove_level(
            system, design.P, lqr_closed_loop(design), design.action_repeat, sampled.rho
        )
        target = ACROBOT_TARGET_SECONDS if name == "acrobot" else PAPER_TARGET_SECONDS
        print(
            f"| {name} | {sampled.rho:.6g} | {sampling:.1f} | {proof.rho:.6g} | "
            f"{proof.rho / sampled.rho:.4f} | {proof.seconds:.1f} | {proof.boxes} | "
            f"{proof.limited_by} | {target:.0f} |",
            flush=True,
        )


if __name__ == "__main__":
    from leoc.cli import quiet_on_broken_pipe

    raise SystemExit(quiet_on_broken_pipe(main))
