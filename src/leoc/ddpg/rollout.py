"""Deterministic evaluation rollouts and the "reached and held the operating point" test.

Definitions (used for the learning curves and the closing measurements):

* An evaluation episode starts from the system's swing-up start distribution (seeded), runs the
  deterministic physical-units policy for the full episode (200 steps) and records the return
  and the state after every step.
* Its *hold start* is the first step ``t`` such that the main coordinate
  (``System.main_coordinate``: angle deviation in degrees for the pendulum and the cart-pole,
  position in metres for the mountain car) stays inside ``[-hold_band, hold_band]`` from step
  ``t`` to the end of the episode; ``None`` if the last state is outside the band.
* The episode *holds the operating point* if it was not terminated (out of bounds) and its hold
  start leaves at least ``min_hold_steps`` steps in the band (``t <= T - min_hold_steps``).
* An evaluation *holds* if all its episodes do.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
import torch
from torch import nn

__all__ = ["EpisodeResult", "EvaluationResult", "evaluate_policy", "run_episode"]

DTYPE = torch.float64


class EpisodeResult(NamedTuple):
    """One deterministic rollout: return, states after each step (T, S), termination."""

    episode_return: float
    states: np.ndarray
    terminated: bool


class EvaluationResult(NamedTuple):
    """Several rollouts of one policy (see the module docstring for the hold test)."""

    mean_return: float
    std_return: float
    returns: list[float]
    hold_starts: list[int | None]  # per episode, None if not held
    held: list[bool]

    @property
    def held_fraction(self) -> float:
        return float(np.mean(self.held)) if self.held else 0.0

    @property
    def all_held(self) -> bool:
        return bool(self.held) and all(self.held)


def run_episode(policy: nn.Module, env: Any, seed: int) -> EpisodeResult:
    """Roll out ``policy`` (float64 (1, D) -> physical (1, F)) on ``env`` from ``reset(seed)``."""
    obs, info = env.reset(seed=seed)
    states, total, terminated, truncated = [], 0.0, False, False
    with torch.no_grad():
        while not (terminated or truncated):
            obs_t = torch.as_tensor(np.asarray(obs, dtype=np.float64), dtype=DTYPE)[None, :]
            action = policy(obs_t)[0].numpy()
            obs, reward, terminated, truncated, info = env.step(action)
            total += float(reward)
            states.append(np.asarray(info["state"], dtype=float))
    return EpisodeResult(total, np.asarray(states), bool(terminated))


def evaluate_policy(
    policy: nn.Module,
    env: Any,
    system: Any,
    seeds: Sequence[int],
    hold_band: float,
    min_hold_steps: int,
) -> EvaluationResult:
    """Roll out ``policy`` once per seed and apply the hold test (module docstring)."""
    returns: list[float] = []
    starts: list[int | None] = []
    held: list[bool] = []
    for seed in seeds:
        episode = run_episode(policy, env, int(seed))
        start = system.hold_step(episode.states, hold_band, min_hold_steps)
        ok = (
            not episode.terminated
            and len(episode.states) >= system.episode_steps
            and start is not None
        )
        returns.append(episode.episode_return)
        starts.append(start if ok else None)
        held.append(bool(ok))
    return EvaluationResult(float(np.mean(returns)), float(np.std(returns)), returns, starts, held)
