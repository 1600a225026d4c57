"""The one closed-loop simulation of a :class:`~leoc.systems.base.System`, batched over starts.

Every rollout in leoc goes through :func:`simulate`: the response tests and robustness sweeps of
:mod:`leoc.evaluation`, PILCO's data collection, the DDPG/TD3 evaluation episodes and the
empirical basins of attraction. So every one of them runs the same closed loop.

Control period. A controller is any callable mapping a float64 observation batch ``(B, O)`` to
actions ``(B, A)``. It decides every :func:`control_period` simulator steps (its
``action_repeat`` attribute, default 1) and its action is held in between (zero-order hold):
a controller keeps the period it was trained at wherever it is evaluated. Disturbances
(``action_offsets``) act on every simulator step, on top of the held action, before the
actuator clip.

Perturbations. ``perturbations`` (:mod:`leoc.systems.perturbations`) make the plant differ
from ``system``: the controller sees noisy observations, the actuator a delayed, scaled or
noisy command, the dynamics friction, pushes or other constants. One
:class:`~leoc.systems.perturbations.PerturbedPlant` per call runs them (the gymnasium
environment runs the same); the recorded observations are those the controller saw, the
recorded actions its commands, the states the plant's. :func:`simulate_settings` runs several
plants in one batch, each on its own rows, with one controller call per decision for all.

Termination. A start whose state leaves the allowed region (``System.out_of_bounds``) gets the
system's ``termination_reward`` for that step (its ``out_of_bounds_reward`` for that step and
each of the steps the episode would still have run) and is frozen from then on (no further
reward, its state repeated), exactly as a gymnasium episode that ends there.

Shapes: ``B`` starts, ``T`` simulator steps, ``S`` state, ``O`` observation, ``A`` action.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import numpy as np
import torch
from torch import Tensor

from leoc.systems.base import DTYPE, System, check_repeat
from leoc.systems.perturbations import Perturbation, PerturbedPlant, PlantRows

#: A controller: batched observations ``(B, D)`` to actions ``(B, A)``.
Controller = Callable[[Tensor], Tensor]


class Trajectory(NamedTuple):
    """One closed-loop episode (``T`` steps taken; fewer than requested if it terminated).

    Attributes
    ----------
    states : (T + 1, S) array
    observations : (T + 1, O) array of what the controller saw (with any observation noise)
    actions : (T, A) array of the commands (held controller output plus offset, clipped; the
        actuator's perturbations, if any, act on them after)
    rewards : (T,) array
    relevance : (T,) array of r(x) at the last decision, for hybrid controllers; else None
    terminated : bool
    action_repeat : int
        The control period the episode ran at (simulator steps per decision).
    """

    states: np.ndarray
    observations: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    relevance: np.ndarray | None
    terminated: bool
    action_repeat: int = 1

    @property
    def total_reward(self) -> float:
        """Sum of the rewards of the episode."""
        return float(np.sum(self.rewards))

    @property
    def steps(self) -> int:
        """Number of steps the episode ran."""
        return int(self.actions.shape[0])


class BatchTrajectory(NamedTuple):
    """``B`` episodes run together; entries after a start's termination are frozen copies.

    Attributes
    ----------
    states : (B, T + 1, S) array
    observations : (B, T + 1, O) array
    actions : (B, T, A) array
    rewards : (B, T) array (0 after termination)
    relevance : (B, T) array or None
    terminated : (B,) bool array
    lengths : (B,) int array of the steps each episode took before it ended
    action_repeat : int
    """

    states: np.ndarray
    observations: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    relevance: np.ndarray | None
    terminated: np.ndarray
    lengths: np.ndarray
    action_repeat: int

    @property
    def total_rewards(self) -> np.ndarray:
        return self.rewards.sum(axis=1)

    def rows(self, index: slice) -> BatchTrajectory:
        """The episodes ``index`` (a slice of the batch) as a batch of their own."""
        relevance = None if self.relevance is None else self.relevance[index]
        return BatchTrajectory(
            self.states[index],
            self.observations[index],
            self.actions[index],
            self.rewards[index],
            relevance,
            self.terminated[index],
            self.lengths[index],
            self.action_repeat,
        )

    def episode(self, index: int) -> Trajectory:
        """Episode ``index`` cut at its own length."""
        length = int(self.lengths[index])
        return Trajectory(
            self.states[index, : length + 1],
            self.observations[index, : length + 1],
            self.actions[index, :length],
            self.rewards[index, :length],
            None if self.relevance is None else self.relevance[index, :length],
            bool(self.terminated[index]),
            self.action_repeat,
        )


def control_period(controller: Any, action_repeat: Any = None) -> int:
    """Simulator steps per decision of ``controller``: ``action_repeat`` where given, else its
    own ``action_repeat``, default 1 (checked: a positive integer)."""
    if action_repeat is None:
        action_repeat = getattr(controller, "action_repeat", 1)
    return check_repeat(action_repeat)


def relevance_function(controller: Any) -> Callable[[Tensor], Tensor] | None:
    """The controller's ``relevance(x)`` method if it is a hybrid (has ``relevance`` and does
    not declare ``is_hybrid = False``), else None."""
    relevance = getattr(controller, "relevance", None)
    if callable(relevance) and getattr(controller, "is_hybrid", True):
        return relevance
    return None


def _check_inputs(
    system: System, starts: Any, steps: int, action_offsets: Any
) -> tuple[Tensor, Tensor]:
    if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 1:
        raise ValueError(f"steps: expected a positive integer, found {steps!r}")
    state = torch.as_tensor(np.asarray(starts, dtype=float), dtype=DTYPE)
    if state.ndim == 1:
        state = state.unsqueeze(0)
    if state.ndim != 2 or state.shape[-1] != system.state_dim:
        raise ValueError(
            f"starts: expected shape ({system.state_dim},) or (B, {system.state_dim}) "
            f"({', '.join(system.state_names)}), found {tuple(state.shape)}"
        )
    if not torch.all(torch.isfinite(state)):
        raise ValueError("starts: expected finite numbers, found NaN or inf")
    offsets = torch.zeros(steps, system.action_dim, dtype=DTYPE)
    if action_offsets is not None:
        given = np.asarray(action_offsets, dtype=float)
        if given.size != steps * system.action_dim:
            raise ValueError(
                f"action_offsets: expected {steps} x {system.action_dim} numbers, "
                f"found shape {given.shape}"
            )
        offsets = torch.as_tensor(given.reshape(steps, system.action_dim), dtype=DTYPE)
    return state, offsets


class _Decision(NamedTuple):
    """What a decision of :func:`simulate` holds until the next one: the controller's ``action``
    ``(B, A)`` and the relevance ``r(x)`` ``(B,)`` it was taken at (zeros for a non-hybrid)."""

    action: Tensor
    relevance: Tensor


def _decide(
    system: System,
    controller: Controller,
    relevance_of: Callable[[Tensor], Tensor] | None,
    obs: Tensor,
    held: _Decision,
) -> _Decision:
    """The controller's decision at the observations ``obs`` ``(B, O)``; the relevance of a
    hybrid (``relevance_of``), else the one ``held`` so far."""
    batch = obs.shape[0]
    action = torch.as_tensor(controller(obs), dtype=DTYPE).reshape(batch, system.action_dim)
    if relevance_of is None:
        return _Decision(action, held.relevance)
    return _Decision(action, torch.as_tensor(relevance_of(obs), dtype=DTYPE).reshape(batch))


@dataclasses.dataclass
class _Episodes:
    """The ``B`` episodes of :func:`simulate` as they run: the current ``state`` ``(B, S)``,
    which starts are still ``alive`` ``(B,)``, the ``lengths`` ``(B,)`` of those that ended
    (``steps`` for the others), and one tensor per step of each record of a
    :class:`BatchTrajectory` (states and observations from the start)."""

    state: Tensor
    alive: Tensor
    lengths: Tensor
    states: list[Tensor]
    observations: list[Tensor]
    actions: list[Tensor] = dataclasses.field(default_factory=list)
    rewards: list[Tensor] = dataclasses.field(default_factory=list)
    relevance: list[Tensor] = dataclasses.field(default_factory=list)

    @classmethod
    def start(cls, plant: PerturbedPlant | PlantRows, state: Tensor, steps: int) -> _Episodes:
        """Episodes of ``steps`` steps from ``state`` ``(B, S)``, every one alive."""
        batch = state.shape[0]
        alive = torch.ones(batch, dtype=torch.bool)
        lengths = torch.full((batch,), steps, dtype=torch.long)
        plant.reset(batch)
        return cls(state, alive, lengths, [state], [plant.observe(state)])

    def advance(
        self,
        plant: PerturbedPlant | PlantRows,
        action: Tensor,
        relevance: Tensor,
        index: int,
        steps: int,
    ) -> None:
        """Simulator step ``index`` (of ``steps``) with ``action`` ``(B, A)``: a start that
        leaves the allowed region ends there (its termination reward), an ended one is frozen
        (zero action and reward, its state and observation repeated)."""
        stepped = plant.step(self.state, action).state
        leaving = self.alive & plant.out_of_bounds(stepped)
        reward = plant.step_reward(self.state, action, stepped, leaving, steps - index - 1)
        self.rewards.append(torch.where(self.alive, reward, torch.zeros_like(reward)))
        self.actions.append(torch.where(self.alive[:, None], action, torch.zeros_like(action)))
        self.relevance.append(relevance)
        self.state = torch.where(self.alive[:, None], stepped, self.state)
        observed = plant.observe(self.state)
        self.observations.append(torch.where(self.alive[:, None], observed, self.observations[-1]))
        self.lengths = torch.where(leaving, torch.as_tensor(index + 1), self.lengths)
        self.alive = self.alive & ~leaving
        self.states.append(self.state)

    def pad(self, steps: int) -> None:
        """Repeat the frozen tail up to ``steps`` steps when every start ended early."""
        pad = steps - len(self.actions)
        if pad > 0:
            self.states += [self.state] * pad
            self.observations += [self.observations[-1]] * pad
            self.actions += [torch.zeros_like(self.actions[-1])] * pad
            self.rewards += [torch.zeros_like(self.rewards[-1])] * pad
            self.relevance += [self.relevance[-1]] * pad

    def result(self, action_repeat: int, with_relevance: bool) -> BatchTrajectory:
        """The records stacked along time (axis 1) as numpy arrays; the relevance only
        ``with_relevance`` (a hybrid controller)."""
        return BatchTrajectory(
            torch.stack(self.states, dim=1).numpy(),
            torch.stack(self.observations, dim=1).numpy(),
            torch.stack(self.actions, dim=1).numpy(),
            torch.stack(self.rewards, dim=1).numpy(),
            torch.stack(self.relevance, dim=1).numpy() if with_relevance else None,
            (~self.alive).numpy(),
            self.lengths.numpy(),
            action_repeat,
        )


def simulate(
    system: System,
    controller: Controller,
    starts: Any,
    steps: int | None = None,
    action_offsets: Any = None,
    action_repeat: int | None = None,
    perturbations: Sequence[Perturbation] = (),
) -> BatchTrajectory:
    """Run ``controller`` on ``system`` from every start at once.

    Parameters
    ----------
    system : System
    controller : callable
        Observation ``(B, O)`` float64 tensor -> action ``(B, A)``.
    starts : (B, S) or (S,) array
    steps : int, optional
        Simulator steps (default ``system.episode_steps``).
    action_offsets : (steps, A) array, optional
        Disturbance added to the held action at every simulator step, before the clip.
    action_repeat : int, optional
        Simulator steps per decision; default the controller's own (:func:`control_period`).
    perturbations : sequence of Perturbation, optional
        The plant's perturbations (module docstring); none by default: ``system`` itself.

    Returns
    -------
    BatchTrajectory
    """
    steps = system.episode_steps if steps is None else steps
    state, offsets = _check_inputs(system, starts, steps, action_offsets)
    repeat = control_period(controller) if action_repeat is None else check_repeat(action_repeat)
    plant = PerturbedPlant(system, perturbations, repeat)
    return _closed_loop(system, controller, plant, state, offsets, repeat)


def simulate_settings(
    system: System,
    controller: Controller,
    settings: Sequence[tuple[Any, Sequence[Perturbation]]],
    steps: int | None = None,
    action_repeat: int | None = None,
) -> list[BatchTrajectory]:
    """:func:`simulate` of several plants at once: ``settings`` holds ``(starts, perturbations)``
    pairs, and setting ``i``'s episodes run on its own
    :class:`~leoc.systems.perturbations.PerturbedPlant` (its random streams, its delay queue, its
    constants) while one controller call per decision serves every setting
    (:class:`~leoc.systems.perturbations.PlantRows`). Returns one :class:`BatchTrajectory` per
    setting, what ``simulate(system, controller, starts, steps, None, action_repeat,
    perturbations)`` gives up to the rounding of the controller's batched arithmetic, except
    that the relevance of an episode after its end is the controller's at its frozen
    observation (``simulate`` repeats the last one taken when every episode has ended). The
    robustness protocol runs every level of a category this way."""
    if not settings:
        raise ValueError("settings: expected at least one (starts, perturbations) pair, found none")
    steps = system.episode_steps if steps is None else steps
    repeat = control_period(controller) if action_repeat is None else check_repeat(action_repeat)
    parts = [_check_inputs(system, starts, steps, None) for starts, _ in settings]
    sizes = [state.shape[0] for state, _ in parts]
    plants = [PerturbedPlant(system, perturbations, repeat) for _, perturbations in settings]
    state = torch.cat([state for state, _ in parts])
    batch = _closed_loop(system, controller, PlantRows(plants, sizes), state, parts[0][1], repeat)
    bounds = np.cumsum([0, *sizes])
    return [batch.rows(slice(a, b)) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]


def _closed_loop(
    system: System,
    controller: Controller,
    plant: PerturbedPlant | PlantRows,
    state: Tensor,
    offsets: Tensor,
    repeat: int,
) -> BatchTrajectory:
    """The loop of :func:`simulate` on ``plant`` from ``state`` ``(B, S)``, ``offsets``
    ``(T, A)`` added to the held action at every step."""
    steps = offsets.shape[0]
    relevance_of = relevance_function(controller)
    episodes = _Episodes.start(plant, state, steps)
    batch = state.shape[0]
    decision = _Decision(
        torch.zeros(batch, system.action_dim, dtype=DTYPE), torch.zeros(batch, dtype=DTYPE)
    )
    with torch.no_grad():
        for index in range(steps):
            if index % repeat == 0:
                obs = episodes.observations[-1]
                decision = _decide(system, controller, relevance_of, obs, decision)
            action = system.clip_action(decision.action + offsets[index])
            episodes.advance(plant, action, decision.relevance, index, steps)
            if not bool(episodes.alive.any()):
                break
    episodes.pad(steps)
    return episodes.result(repeat, with_relevance=relevance_of is not None)


def rollout(
    system: System,
    controller: Controller,
    initial_state: Any,
    steps: int | None = None,
    action_offsets: Any = None,
    action_repeat: int | None = None,
    perturbations: Sequence[Perturbation] = (),
) -> Trajectory:
    """One episode of :func:`simulate` from ``initial_state`` ``(S,)``, cut where it ended."""
    start = np.asarray(initial_state, dtype=float)
    if start.ndim != 1:
        raise ValueError(
            f"initial_state: expected shape ({system.state_dim},), found {start.shape}"
        )
    batch = simulate(
        system, controller, start[None], steps, action_offsets, action_repeat, perturbations
    )
    return batch.episode(0)


def holds(system: System, trajectory: Trajectory) -> bool:
    """Whether an episode reached and held the operating point (:meth:`System.hold_step` on its
    states after each step, with the system's band and minimum duration)."""
    return hold_step(system, trajectory) is not None


def hold_step(system: System, trajectory: Trajectory) -> int | None:
    """First step from which the episode holds the operating point, or None (terminated, out of
    the band at the end, or inside for fewer than ``system.hold_min_steps`` steps)."""
    return system.hold_step(trajectory.states[1:], terminated=trajectory.terminated)


class RandomController:
    """Uniform random actions within the actuator limits, from a seeded numpy generator
    (PILCO's initial rollouts). Decides at the given control period like any controller."""

    is_hybrid = False

    def __init__(self, system: System, rng: np.random.Generator, action_repeat: int = 1):
        self.limit = system.action_limit
        self.action_dim = system.action_dim
        self.rng = rng
        self.action_repeat = check_repeat(action_repeat)

    def __call__(self, obs: Tensor) -> Tensor:
        batch = obs.shape[0]
        values = self.rng.uniform(-self.limit, self.limit, size=(batch, self.action_dim))
        return torch.as_tensor(values, dtype=DTYPE)
