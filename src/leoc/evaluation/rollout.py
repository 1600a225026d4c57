"""Closed-loop rollouts on the pure step functions, and the impulse/step response tests.

A *controller* is any callable mapping a float64 observation batch ``(B, O)`` to physical
actions ``(B, A)`` (a torch module such as :class:`~leoc.policies.HybridPolicy`). When it has a
``relevance(x)`` method (and no ``is_hybrid = False``), r(x) along the rollout is recorded too.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Literal, NamedTuple

import numpy as np
import torch
from torch import Tensor

from leoc.evaluation.metrics import ResponseMetrics, response_metrics
from leoc.systems.base import DTYPE, System

Controller = Callable[[Tensor], Tensor]
RESPONSE_TESTS = ("impulse", "step")
ResponseTest = Literal["impulse", "step"]
IMPULSE_MAGNITUDE = -1.0  # added to the first action only
STEP_MAGNITUDE = -0.2  # added to every action
RESPONSE_STEPS = 200


class Trajectory(NamedTuple):
    """One closed-loop rollout (``T`` steps taken; ``T`` < requested if it terminated).

    Attributes
    ----------
    states : (T + 1, S) array
    observations : (T + 1, O) array
    actions : (T, A) array of the actions applied (controller output plus offset, clipped)
    rewards : (T,) array
    relevance : (T,) array of r(x) for hybrid controllers, else None
    terminated : bool
    """

    states: np.ndarray
    observations: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    relevance: np.ndarray | None
    terminated: bool

    @property
    def total_reward(self) -> float:
        return float(np.sum(self.rewards))


class ResponseResult(NamedTuple):
    """An impulse or step response: the trajectory, the main-coordinate deviation e(t) in
    report units (degrees or metres), and its metrics."""

    test: str
    trajectory: Trajectory
    deviation: np.ndarray
    metrics: ResponseMetrics


def relevance_function(controller: Controller) -> Callable[[Tensor], Tensor] | None:
    """The controller's ``relevance(x)`` method if it is a hybrid (has ``relevance`` and does
    not declare ``is_hybrid = False``), else None."""
    relevance = getattr(controller, "relevance", None)
    if callable(relevance) and getattr(controller, "is_hybrid", True):
        return relevance
    return None


def rollout(
    system: System,
    controller: Controller,
    initial_state: np.ndarray,
    steps: int | None = None,
    action_offsets: np.ndarray | None = None,
) -> Trajectory:
    """Run ``controller`` on ``system`` from ``initial_state``.

    Parameters
    ----------
    system : System
    controller : callable
        Observation ``(1, O)`` float64 tensor -> action ``(1, A)``.
    initial_state : (S,) array
    steps : int, optional
        Number of steps (default ``system.episode_steps``); stops early when the state leaves
        the allowed region.
    action_offsets : (steps, A) array, optional
        Added to the controller's action before the actuator clip (disturbance input).
    """
    steps = system.episode_steps if steps is None else int(steps)
    if steps < 1:
        raise ValueError(f"steps: expected a positive integer, found {steps}")
    state = torch.as_tensor(np.asarray(initial_state, dtype=float), dtype=DTYPE).reshape(1, -1)
    if state.shape[-1] != system.state_dim:
        raise ValueError(
            f"initial_state: expected {system.state_dim} entries, found {state.shape[-1]}"
        )
    offsets = np.zeros((steps, system.action_dim))
    if action_offsets is not None:
        offsets = np.asarray(action_offsets, dtype=float).reshape(steps, system.action_dim)
    relevance_of = relevance_function(controller)
    states, observations, actions, rewards, relevance = [state], [], [], [], []
    terminated = False
    with torch.no_grad():
        for index in range(steps):
            obs = system.observe(state)
            observations.append(obs)
            action = controller(obs)
            if relevance_of is not None:
                relevance.append(float(relevance_of(obs).reshape(-1)[0]))
            action = torch.as_tensor(action, dtype=DTYPE).reshape(1, system.action_dim)
            action = system.clip_action(action + torch.as_tensor(offsets[index], dtype=DTYPE))
            rewards.append(float(system.reward_fn(state, action)[0]))
            state = system.step_fn(state, action)
            actions.append(action)
            states.append(state)
            if bool(system.out_of_bounds(state)[0]):
                rewards[-1] = float(system.out_of_bounds_reward)
                terminated = True
                break
        observations.append(system.observe(state))
    return Trajectory(
        torch.cat(states).numpy(),
        torch.cat(observations).numpy(),
        torch.cat(actions).numpy(),
        np.asarray(rewards),
        np.asarray(relevance) if relevance_of is not None else None,
        terminated,
    )


def response_offsets(test: ResponseTest, steps: int, action_dim: int = 1) -> np.ndarray:
    """Disturbance input of a response test: ``impulse`` adds -1.0 to the first action,
    ``step`` adds -0.2 to every action."""
    if test not in RESPONSE_TESTS:
        raise ValueError(f"test: expected one of {RESPONSE_TESTS}, found {test!r}")
    offsets = np.zeros((steps, action_dim))
    if test == "impulse":
        offsets[0] = IMPULSE_MAGNITUDE
    else:
        offsets[:] = STEP_MAGNITUDE
    return offsets


def response_test(
    system: System,
    controller: Controller,
    test: ResponseTest = "impulse",
    steps: int = RESPONSE_STEPS,
) -> ResponseResult:
    """Impulse or step response from the operating point, with its metrics.

    The system starts exactly at its operating point; ``impulse`` adds -1.0 to the first
    action, ``step`` adds -0.2 to every action, for ``steps`` steps. The deviation e(t) is
    the main coordinate (degrees for pendulum and cart-pole, metres for mountain car),
    ``steps + 1`` samples from t = 0; metrics use ``system.settling_band``.
    """
    offsets = response_offsets(test, steps, system.action_dim)
    trajectory = rollout(system, controller, system.operating_state, steps, offsets)
    deviation = system.main_coordinate(trajectory.states)
    return ResponseResult(
        test, trajectory, deviation, response_metrics(deviation, system.settling_band)
    )


def hold_step(system: System, states: np.ndarray, band: float | None = None) -> int | None:
    """First step from which the main coordinate stays within ``band`` (default
    ``system.hold_band``: 5 degrees for the angle systems, 0.05 m for mountain car) until the
    end of ``states``; None if it is outside at the end (see :meth:`System.hold_step`)."""
    return system.hold_step(states, band)
