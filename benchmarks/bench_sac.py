"""Training cost of SAC against DDPG: wall seconds per 1000 environment steps on one system.

Times ``model.learn`` (environment step, action selection, replay sampling and one gradient
update per step; SAC's update trains the actor, two critics against two target critics and the
entropy coefficient) with each learner's leoc settings (``DDPGConfig.for_system(system, algo)``:
400-300 networks; DDPG minibatch 64, SAC minibatch 256), evaluation switched off. A third
learner, SAC with DDPG's minibatch of 64, separates the cost of SAC's update from the cost of its
larger batch. The learners train side by side in one process after one warm-up episode each
(the 200 steps before the first update), in chunks whose order rotates, so that the load of a
shared machine falls on all alike.

Usage::

    python benchmarks/bench_sac.py [--system pendulum] [--steps 1000] [--chunk 100]
                                   [--baseline] [--threads 1]

Prints seconds per 1000 steps of each learner and its ratio to DDPG's.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import torch

from leoc.sb3 import DDPGConfig, build_model
from leoc.systems import make_env

WARMUP_STEPS = 200  # = learning_starts: the first timed step already trains
PER_STEPS = 1000  # the figure's unit: seconds per this many steps
NO_EVALUATION = 10**9
DDPG_BATCH = 64
#: The learners timed: label -> (algo, DDPGConfig overrides).
LEARNERS: dict[str, tuple[str, dict[str, Any]]] = {
    "ddpg": ("ddpg", {}),
    "sac": ("sac", {}),
    "sac (batch 64)": ("sac", {"batch_size": DDPG_BATCH}),
}


def _model(system: str, algo: str, hybrid: bool, overrides: dict[str, Any], seed: int) -> Any:
    config = DDPGConfig.for_system(
        system,
        algo,
        hybrid=hybrid,
        learning_starts=WARMUP_STEPS,
        eval_interval=NO_EVALUATION,
        **overrides,
    )
    return build_model(config, seed, make_env(system))


def time_learners(system: str, hybrid: bool, steps: int, chunk: int, seed: int) -> dict[str, float]:
    """Total seconds of ``steps`` training steps per learner (chunks in rotating order)."""
    models = {
        label: _model(system, algo, hybrid, overrides, seed)
        for label, (algo, overrides) in LEARNERS.items()
    }
    for model in models.values():
        model.learn(total_timesteps=WARMUP_STEPS)
    seconds = dict.fromkeys(models, 0.0)
    labels = list(models)
    for index in range(steps // chunk):
        shift = index % len(labels)
        for label in labels[shift:] + labels[:shift]:
            start = time.perf_counter()
            models[label].learn(total_timesteps=chunk, reset_num_timesteps=False)
            seconds[label] += time.perf_counter() - start
    return seconds


def main(argv: list[str] | None = None) -> None:
    """Run the benchmark and print its table."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--system", default="pendulum")
    parser.add_argument("--steps", type=int, default=PER_STEPS, help="timed steps per learner")
    parser.add_argument("--chunk", type=int, default=100, help="steps per turn")
    parser.add_argument("--baseline", action="store_true", help="baselines, not hybrids")
    parser.add_argument("--threads", type=int, default=1, help="torch threads")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    kind = "baseline" if args.baseline else "hybrid"
    print(f"system={args.system} {kind} steps={args.steps} threads={args.threads}")
    seconds = time_learners(args.system, not args.baseline, args.steps, args.chunk, seed=0)
    reference = seconds["ddpg"]
    for label, total in seconds.items():
        per = total / args.steps * PER_STEPS
        print(f"{label:15s} {per:7.1f} s per {PER_STEPS} steps   x{total / reference:4.2f} DDPG")


if __name__ == "__main__":
    from leoc.cli import quiet_on_broken_pipe

    raise SystemExit(quiet_on_broken_pipe(main))
