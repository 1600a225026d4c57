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

Measured on this project's 2-core machine (2026-11-28, beside a one-core background job), the
smoke budget (3 levels, 1 episode): a trained smoke SAC hybrid of the mountain car 16.6 s one
setting at a time, 7.2 s batched; its LQR 9.2 s and 6.9 s (under the profiler). The quick budget
on a smoke DDPG hybrid of the pendulum: 38-40 s and 17 s. The same episodes held in every case.
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
