"""Time of the robustness protocol (``leoc robustness``) on one controller, batched and not.

For each system given: the protocol (:func:`leoc.evaluation.robustness_protocol.run_protocol`)
of its LQR and of the paper-relevance hybrid of that LQR with a seeded, untrained 400x300 actor
(leoc's DDPG/TD3 size), at the levels and episodes asked, run as leoc runs it (every level and
start kind of a category in one batch, :func:`leoc.systems.rollout.simulate_settings`) and as
it ran before (one :func:`~leoc.systems.rollout.simulate` per level and start kind), with the
speed-up and whether the two held the same episodes. One torch thread.

Usage::

    python benchmarks/bench_robustness_protocol.py [SYSTEM ...] [--levels 5] [--episodes 2]

The defaults are the ``quick`` profile's budget; the ``paper`` profile's is
``--levels 21 --episodes 5``.

Measured on this project's 2-core machine (2026-11-28, beside niced background jobs), the
defaults (5 levels x 2 episodes), one at a time -> batched: pendulum LQR 14.8 -> 6.3 s (2.35x),
seeded hybrid 31.8 -> 10.6 s (3.00x); cart-pole 12.2 -> 5.5 s (2.20x), 21.8 -> 9.3 s (2.34x);
mountain car 13.6 -> 6.3 s (2.15x), 29.5 -> 9.8 s (3.01x). The same episodes held in every case.
At the paper's budget (21 x 5) the LQR: 57.4 -> 18.3 s, 46.8 -> 19.7 s, 61.9 -> 19.8 s
(docs/user_guide/robustness_protocol.md).
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


def _one_at_a_time(system, controller, starts, settings):
    """The protocol's held episodes, one simulate per level and start kind (before batching)."""
    return {
        (kind, index): protocol._held(system, controller, starts[kind], settings[kind][index])
        for kind in starts
        for index in range(len(settings[kind]))
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
