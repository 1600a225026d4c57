"""Time of the robustness protocol (``leoc robustness``) on one controller, batched and not.

For each system given: the protocol (:func:`leoc.evaluation.robustness_protocol.run_protocol`)
of its LQR and of the paper-relevance hybrid of that LQR with a seeded, untrained 400x300 actor
(leoc's DDPG/TD3 size), at the levels and episodes asked, run as leoc runs it (every setting of
every category in one batch per start kind, :func:`leoc.systems.rollout.simulate_settings`) and
as it ran before (one :func:`~leoc.systems.rollout.simulate` per level and start kind), with the
speed-up and whether the two held the same episodes. One torch thread.

Usage::

    python benchmarks/bench_robustness_protocol.py [SYSTEM ...] [--levels 5] [--episodes 2]

The defaults are the ``quick`` profile's budget; the ``paper`` profile's is
``--levels 21 --episodes 5``.

Measured on this project's 2-core machine (2026-11-29, beside niced background jobs), the
defaults (5 levels x 2 episodes), one at a time -> batched: pendulum LQR 14.3 -> 5.8 s (2.45x),
seeded hybrid 29.7 -> 6.6 s (4.48x); cart-pole 10.9 -> 5.7 s (1.92x), 21.3 -> 8.9 s (2.39x);
mountain car 13.4 -> 5.5 s (2.44x), 26.0 -> 6.8 s (3.83x). The same episodes held in every case.
Batched by category instead (the previous way, 2026-11-28's commit be653e6) the hybrids took 10.0,
8.5 and 10.2 s; at the paper's budget (21 x 5) the two batchings measured the same within the
machine's noise (docs/user_guide/robustness_protocol.md).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import torch

import leoc.evaluation.robustness_protocol as protocol
from leoc.control import design_lqr
from leoc.policies.held import lqr_controller
from leoc.systems import make_system

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_controller_proof import seeded_hybrid  # noqa: E402


def _one_at_a_time(system, controller, starts, settings, progress=None):
    """The protocol's held episodes, one simulate per level and start kind (before batching)."""
    return {
        kind: [
            protocol._held(system, controller, starts[kind], setting) for setting in settings[kind]
        ]
        for kind in starts
    }


def _timed(system, controller, levels: int, episodes: int, batched: bool):
    """The protocol's result and wall time, batched (leoc's way) or one setting at a time."""
    chosen = protocol._held_everywhere
    if not batched:
        protocol._held_everywhere = _one_at_a_time
    try:
        started = time.perf_counter()
        result = protocol.run_protocol(system, controller, levels=levels, episodes=episodes)
        return result, time.perf_counter() - started
    finally:
        protocol._held_everywhere = chosen


def _row(name: str, label: str, system, controller, levels: int, episodes: int) -> str:
    alone, alone_seconds = _timed(system, controller, levels, episodes, batched=False)
    together, together_seconds = _timed(system, controller, levels, episodes, batched=True)
    same = alone.as_dict()["categories"] == together.as_dict()["categories"]
    return (
        f"| {name} | {label} | {alone_seconds:.1f} | {together_seconds:.1f} | "
        f"{alone_seconds / together_seconds:.2f}x | {together.score():.3f} | "
        f"{'yes' if same else 'NO'} |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("systems", nargs="*", default=["pendulum", "mountaincar"])
    parser.add_argument("--levels", type=int, default=5, help="levels per category (>= 2)")
    parser.add_argument("--episodes", type=int, default=2, help="episodes per level and start")
    args = parser.parse_args()
    torch.set_num_threads(1)
    print(f"torch {torch.__version__}, 1 CPU thread, {args.levels} levels x {args.episodes} ep.")
    print("| system | controller | one at a time [s] | batched [s] | speed-up | score | same |")
    print("|---|---|---|---|---|---|---|")
    for name in args.systems:
        system = make_system(name)
        design = design_lqr(system)
        for label, controller in (
            ("LQR", lqr_controller(design)),
            ("seeded hybrid", seeded_hybrid(system, design)),
        ):
            print(_row(name, label, system, controller, args.levels, args.episodes), flush=True)


if __name__ == "__main__":
    main()
