"""Training speed of SB3 DDPG/TD3/SAC with the LEOC hybrid actor against the baseline MLP actor.

Measures environment steps per second of ``model.learn`` (environment stepping, action
selection, replay and one gradient update per step: everything training does) with the paper's
settings (400-300 actor and critic, batch 64; SAC: its own settings, batch 256), evaluation
switched off. A hybrid and a baseline model train side by side in one process, alternating
chunks of 100 steps (A B B A ...), so that the load of a shared machine hits both alike; the
overhead is the median of the per-chunk time ratios (and, for reference, the ratio of total
times). Also prints the cost of one actor forward and backward pass on a batch of 64 (the part
the hybrid changes) and of one ``predict`` call. ``benchmarks/bench_sac.py`` sets SAC's cost
beside DDPG's.

Usage::

    python benchmarks/bench_ddpg.py [--system pendulum] [--algo ddpg] [--steps 2000]
                                    [--chunk 100]
                                    [--repeats 2] [--threads 1]

The issue's target: hybrid overhead under 10% of the baseline's steps per second.
"""

from __future__ import annotations

import argparse
import statistics
import time
from typing import Any

import numpy as np
import torch

from leoc.sb3 import DDPGConfig, build_model
from leoc.systems import make_env

WARMUP_STEPS = 200  # = learning_starts: the first timed step already trains
MICRO_REPEATS = 300
MICRO_BATCH = 64
OVERHEAD_TARGET = 0.10


def _model(system: str, algo: str, hybrid: bool, seed: int) -> Any:
    config = DDPGConfig.for_system(system, algo, hybrid=hybrid, learning_starts=WARMUP_STEPS)
    return build_model(config, seed, make_env(system))


def time_training_interleaved(
    system: str, algo: str, steps: int, chunk: int, seed: int
) -> dict[bool, list[float]]:
    """Seconds per ``chunk`` steps of ``learn``, hybrid and baseline trained side by side.

    Both models first run one warm-up episode (filling the buffer up to ``learning_starts``),
    then alternate chunks of ``chunk`` training steps (order swapped every chunk), so that the
    load of a shared machine falls on both alike.
    """
    models = {hybrid: _model(system, algo, hybrid, seed) for hybrid in (False, True)}
    for model in models.values():
        model.learn(total_timesteps=WARMUP_STEPS)
    seconds: dict[bool, list[float]] = {False: [], True: []}
    for index in range(steps // chunk):
        for hybrid in (False, True) if index % 2 == 0 else (True, False):
            start = time.perf_counter()
            models[hybrid].learn(total_timesteps=chunk, reset_num_timesteps=False)
            seconds[hybrid].append(time.perf_counter() - start)
    return seconds


def time_actor(system: str, algo: str, hybrid: bool) -> tuple[float, float]:
    """(actor forward+backward on a batch of 64, predict on one observation), in microseconds."""
    model = _model(system, algo, hybrid, seed=0)
    obs_dim = model.observation_space.shape[0]
    batch = torch.randn(MICRO_BATCH, obs_dim)
    single = np.zeros(obs_dim)
    start = time.perf_counter()
    for _ in range(MICRO_REPEATS):
        model.actor.optimizer.zero_grad()
        model.actor(batch).sum().backward()
    train_us = (time.perf_counter() - start) / MICRO_REPEATS * 1e6
    start = time.perf_counter()
    for _ in range(MICRO_REPEATS):
        model.predict(single, deterministic=True)
    predict_us = (time.perf_counter() - start) / MICRO_REPEATS * 1e6
    return train_us, predict_us


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--system", default="pendulum")
    parser.add_argument("--algo", default="ddpg", choices=["ddpg", "td3", "sac"])
    parser.add_argument("--steps", type=int, default=2000, help="timed steps per run")
    parser.add_argument("--chunk", type=int, default=100, help="steps per alternation")
    parser.add_argument("--repeats", type=int, default=2, help="pairs of fresh models")
    parser.add_argument("--threads", type=int, default=1, help="torch threads")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)

    print(f"system={args.system} algo={args.algo} steps={args.steps} threads={args.threads}")
    for hybrid in (False, True):
        train_us, predict_us = time_actor(args.system, args.algo, hybrid)
        name = "hybrid  " if hybrid else "baseline"
        print(
            f"{name} actor fwd+bwd (B=64): {train_us:8.1f} us   predict (B=1): {predict_us:7.1f} us"
        )

    seconds: dict[bool, list[float]] = {False: [], True: []}
    for repeat in range(args.repeats):
        run = time_training_interleaved(args.system, args.algo, args.steps, args.chunk, repeat)
        for hybrid in (False, True):
            seconds[hybrid].extend(run[hybrid])
        rates = {h: args.steps / sum(run[h]) for h in (False, True)}
        print(
            f"repeat {repeat}: baseline {rates[False]:7.1f} steps/s, "
            f"hybrid {rates[True]:7.1f} steps/s"
        )
    baseline = len(seconds[False]) * args.chunk / sum(seconds[False])
    hybrid = len(seconds[True]) * args.chunk / sum(seconds[True])
    ratios = [h / b - 1.0 for b, h in zip(seconds[False], seconds[True], strict=True)]
    overhead = statistics.median(ratios)
    print(f"overall steps/s: baseline {baseline:.1f}, hybrid {hybrid:.1f}")
    print(f"hybrid overhead, total time: {baseline / hybrid - 1.0:+.1%}")
    verdict = "OK" if overhead < OVERHEAD_TARGET else "ABOVE TARGET"
    print(
        f"hybrid overhead, median of {len(ratios)} paired chunks: {overhead:+.1%} "
        f"(target < {OVERHEAD_TARGET:.0%}: {verdict})"
    )


if __name__ == "__main__":
    from leoc.cli import quiet_on_broken_pipe

    raise SystemExit(quiet_on_broken_pipe(main))
