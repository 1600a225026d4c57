"""PILCO's real rollouts: one episode of the shared closed-loop simulation, turned into GP data.

Time steps: the simulator runs at ``system.dt``; the controller decides every ``repeat`` steps
and holds its action in between (zero-order hold), which is the map the GP learns. A 200-step
episode is therefore ``ceil(200 / repeat)`` decisions; only complete held decisions (all
``repeat`` steps run before the episode ended) become GP data. The episode itself is
:func:`leoc.systems.rollout.rollout`, the same simulation that evaluates the controller.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from leoc.systems.base import System
from leoc.systems.perturbations import Perturbation
from leoc.systems.rollout import Controller, Trajectory, hold_step, rollout


class Rollout(NamedTuple):
    """One episode and its GP data.

    Attributes
    ----------
    trajectory : Trajectory
        States (T+1, S), actions (T, F), rewards (T,), termination.
    inputs : (K, O + F) array
        Observation and held action at each of the K complete decisions.
    targets : (K, S) array
        State change over the ``repeat`` steps of each decision.
    """

    trajectory: Trajectory
    inputs: np.ndarray
    targets: np.ndarray

    @property
    def steps(self) -> int:
        return self.trajectory.steps

    @property
    def total_return(self) -> float:
        return self.trajectory.total_reward


def run_rollout(
    system: System,
    controller: Controller,
    start: np.ndarray,
    steps: int,
    repeat: int,
    perturbations: Sequence[Perturbation] = (),
) -> Rollout:
    """Run ``steps`` simulator steps from ``start`` with ``controller`` deciding every
    ``repeat`` steps, and cut the episode into GP data (see the module docstring). With
    ``perturbations`` the episode runs on that perturbed plant: the inputs are the observations
    the controller saw (noisy ones with observation noise), the targets the plant's state
    changes."""
    trajectory = rollout(
        system, controller, start, steps, action_repeat=repeat, perturbations=perturbations
    )
    decisions = trajectory.steps // repeat
    index = np.arange(decisions) * repeat
    observations = trajectory.observations[index]
    actions = trajectory.actions[index]
    targets = trajectory.states[index + repeat] - trajectory.states[index]
    inputs = np.concatenate([observations, actions], axis=1)
    return Rollout(
        trajectory,
        inputs.reshape(-1, system.obs_dim + system.action_dim),
        targets.reshape(-1, system.state_dim),
    )


def hold_start(system: System, rollout_: Rollout) -> int | None:
    """First step from which the episode holds the operating point (``System.hold_step``:
    the system's band and minimum duration; None if it terminated or did not hold)."""
    return hold_step(system, rollout_.trajectory)
