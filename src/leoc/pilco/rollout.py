"""Rollouts on the real system (the pure batched step function, no gym overhead) and the
"reached and held the operating point" test.

Time steps: the simulator runs at ``system.dt``; the controller decides every ``repeat`` steps
and holds its action in between (zero-order hold), which is the map the GP learns. A 200-step
episode is therefore ``ceil(200 / repeat)`` decisions, the last one possibly held for fewer steps.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np
import torch

from leoc.systems.base import DTYPE, System

ActionFn = Callable[[np.ndarray], np.ndarray]


class Rollout(NamedTuple):
    """One episode. ``states`` (T+1, S), ``actions`` (T, F), ``rewards`` (T,);
    ``inputs`` (K, O+F) and ``targets`` (K, S) are the K complete held decisions as GP data:
    (observation, action) -> state change over ``repeat`` steps."""

    states: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    inputs: np.ndarray
    targets: np.ndarray
    terminated: bool

    @property
    def steps(self) -> int:
        return int(self.actions.shape[0])

    @property
    def total_return(self) -> float:
        return float(self.rewards.sum())


def run_rollout(
    system: System, act: ActionFn, start: np.ndarray, steps: int, repeat: int
) -> Rollout:
    """Run ``steps`` simulator steps from ``start``, asking ``act(observation)`` every ``repeat``.

    The episode ends early when the state leaves the allowed region; that step's reward is the
    system's ``out_of_bounds_reward``, exactly as in the gymnasium environment.
    """
    state = torch.as_tensor(start, dtype=DTYPE)[None]
    states, actions, rewards = [state[0].numpy()], [], []
    inputs, targets = [], []
    terminated = False
    action = None
    decision_state = None
    for step in range(steps):
        if step % repeat == 0:
            obs = system.observe(state)[0].numpy()
            action = np.asarray(act(obs), dtype=float).reshape(system.action_dim)
            decision_state, decision_input = state[0].numpy(), np.concatenate([obs, action])
        action_t = torch.as_tensor(action, dtype=DTYPE)[None]
        reward = float(system.reward_fn(state, action_t)[0])
        state = system.step_fn(state, action_t)
        terminated = bool(system.out_of_bounds(state)[0])
        rewards.append(system.out_of_bounds_reward if terminated else reward)
        states.append(state[0].numpy())
        actions.append(action)
        if (step + 1) % repeat == 0:
            inputs.append(decision_input)
            targets.append(state[0].numpy() - decision_state)
        if terminated:
            break
    return Rollout(
        np.asarray(states),
        np.asarray(actions),
        np.asarray(rewards),
        np.asarray(inputs).reshape(-1, system.obs_dim + system.action_dim),
        np.asarray(targets).reshape(-1, system.state_dim),
        terminated,
    )


def random_action_fn(system: System, rng: np.random.Generator) -> ActionFn:
    """Uniform random actions in the actuator limits (PILCO's initial rollouts)."""
    limit = system.action_limit
    return lambda obs: rng.uniform(-limit, limit, size=system.action_dim)


def policy_action_fn(policy: torch.nn.Module) -> ActionFn:
    """Deterministic action of a torch policy on one observation."""

    def act(obs: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return policy(torch.as_tensor(obs, dtype=DTYPE)[None])[0].numpy()

    return act


def hold_start(
    system: System, rollout: Rollout, band: float, min_steps: int, episode_steps: int
) -> int | None:
    """First step from which the main coordinate stays within ``band`` to the episode's end.

    The main coordinate is ``system.main_coordinate`` (degrees for angles, position otherwise)
    of the states after each step. Returns None if the episode ended early (out of bounds), never
    entered the band for good, or held it for fewer than ``min_steps`` steps.
    """
    if rollout.terminated or rollout.steps < episode_steps:
        return None
    return system.hold_step(rollout.states[1:], band, min_steps)
