"""Boxes per second of the proof's inner loop: one closed-loop enclosure (value and Jacobian)
of a hybrid whose learned part is a 400x300 actor (leoc's DDPG/TD3 size), on a chosen device.

Each batch of boxes in V's coordinates goes through what :func:`leoc.control.proof.prove_level`
evaluates per box: the observation, the hybrid (LQR, paper relevance, actor) and the held plant
on interval jets, at a box and at its centre. Seeded actor weights; the figure does not depend
on what the actor learned.

Usage::

    python benchmarks/bench_interval_mlp.py [--system pendulum] [--device cpu|cuda]
        [--threads 1] [--batches 512 4096 16384 65536] [--repeats 3]

Measured 2026-11-28 on an NVIDIA H200 machine: pendulum 2.06 million boxes/s (batch 262144) on
the GPU against 8.4 thousand on its 16 CPU threads; cart-pole 1.44 million against 6.7
thousand. (Issue 42's plain-torch sketch of the propagation alone, without the plant, the
relevance or rounding: 3.6 million on an H100, 22-40 thousand on 16 CPU threads.)

Measured 2026-12-07 on 2 loaded AMD EPYC cores (one thread, CPU time, cart-pole): the
in-place radii and the kink-only hull of :mod:`leoc.control.intervals` (same bits) took a
16384-box batch from 916-988 to 2056-2132 boxes/s (its gradient temporaries are 210 MB each);
at 512 boxes, the batch :func:`leoc.control.certify_controller` uses on the CPU, the rate stayed
within the noise (3.2-3.9 thousand), where the matrix products are 40% of the time.
"""

from __future__ import annotations

import argparse
import time

import torch

from bench_controller_proof import seeded_hybrid
from leoc.control import design_lqr
from leoc.control.proof import _enclose, _frame, _on_device, check_device
from leoc.systems import make_system
from leoc.systems.base import DTYPE


def _rate(system, controller, frame, batch: int, repeats: int, device) -> float:
    """Boxes per second over ``repeats`` timed batches (after one warm-up batch)."""
    size = frame.factor.shape[0]
    generator = torch.Generator().manual_seed(batch)
    centre = (0.1 * torch.randn(batch, size, generator=generator, dtype=DTYPE)).to(device)
    radius = torch.full_like(centre, 1e-3)
    timings = []
    for _ in range(repeats + 1):
        if device.type == "cuda":
            torch.cuda.synchronize()
        started = time.perf_counter()
        with torch.no_grad(), torch.device(device):
            _enclose(system, controller, 1, frame, centre, radius)
            _enclose(system, controller, 1, frame, centre, None)
        if device.type == "cuda":
            torch.cuda.synchronize()
        timings.append(time.perf_counter() - started)
    return batch / min(timings[1:])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--system", default="pendulum")
    parser.add_argument("--device", default="cpu", help="cpu (default) or cuda[:N]")
    parser.add_argument("--threads", type=int, default=1, help="CPU threads (default 1)")
    parser.add_argument("--batches", type=int, nargs="+", default=[512, 4096, 16384, 65536])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    device = check_device(args.device)
    system = make_system(args.system)
    design = design_lqr(system)
    controller = _on_device(seeded_hybrid(system, design), device)
    with torch.device(device):
        frame = _frame(system, design.P)
    print(f"{args.system}, 400x300 hybrid, {device}, {args.threads} CPU thread(s)")
    print("| boxes per batch | boxes/s |")
    print("|---|---|")
    for batch in args.batches:
        rate = _rate(system, controller, frame, batch, args.repeats, device)
        print(f"| {batch} | {rate:,.0f} |", flush=True)


if __name__ == "__main__":
    main()
