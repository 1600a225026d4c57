"""Robustness sweeps, relevance traces and per-controller evaluation summaries.

Robustness (paper figure 8): the controller, trained on the nominal system, runs on copies of
the system whose masses or gravity are scaled by 0.5x, 1.0x, ..., 5.0x, started at the
operating point (optionally offset in its main coordinate), for one 200-step episode. From the
exact operating point a controller with G(a) = u_eq stays there on every scaled system (the
equilibrium does not depend on mass or g); a learned controller whose action at a is not u_eq
drifts away. We record the
return and whether the system stays at the operating point (:func:`hold_step`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from leoc.evaluation.rollout import Controller, hold_step, rollout
from leoc.systems import make_system
from leoc.systems.base import System

SCALE_FACTORS = tuple(np.round(np.arange(0.5, 5.01, 0.5), 2).tolist())
SCALED_PARAMETERS = ("mass", "gravity")
# Default offset of the main coordinate at the start of a robustness run (rad or m).
ROBUSTNESS_OFFSET = 0.0


class RobustnessPoint(NamedTuple):
    parameter: str
    scale: float
    total_reward: float
    held: bool


class RelevanceTrace(NamedTuple):
    """Main coordinate (report units) and relevance r(x) along a swing-up, per step."""

    time: np.ndarray
    main: np.ndarray
    relevance: np.ndarray


def robustness_start(system: System, main_offset: float = ROBUSTNESS_OFFSET) -> np.ndarray:
    """The operating point with the main coordinate offset by ``main_offset`` (rad or m)."""
    offset = np.zeros(system.state_dim)
    offset[system.main_index] = main_offset
    return system.sample_start(np.random.default_rng(0), "operating_point", offset)


def robustness_sweep(
    system_name: str,
    controller: Controller,
    parameters: Sequence[str] = SCALED_PARAMETERS,
    scales: Sequence[float] = SCALE_FACTORS,
    main_offset: float = ROBUSTNESS_OFFSET,
) -> list[RobustnessPoint]:
    """Return and hold flag of ``controller`` on every scaled copy of the system."""
    points = []
    for parameter in parameters:
        for scale in scales:
            system = make_system(system_name, **{parameter: float(scale)})
            trajectory = rollout(system, controller, robustness_start(system, main_offset))
            held = hold_step(system, trajectory.states) is not None and not trajectory.terminated
            points.append(RobustnessPoint(parameter, float(scale), trajectory.total_reward, held))
    return points


def relevance_trace(system_name: str, controller: Controller, seed: int) -> RelevanceTrace | None:
    """Swing-up from the seeded start; None if the controller has no relevance (not hybrid)."""
    system = make_system(system_name)
    start = system.sample_start(np.random.default_rng(seed), "swing_up")
    trajectory = rollout(system, controller, start)
    if trajectory.relevance is None:
        return None
    steps = len(trajectory.relevance)
    return RelevanceTrace(
        np.arange(steps) * system.dt,
        system.main_coordinate(trajectory.states[:steps]),
        trajectory.relevance,
    )
