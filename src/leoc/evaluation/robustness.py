"""Robustness sweeps (paper figure 8) and relevance traces (figure 4).

Robustness. The controller, trained on the nominal system, runs on copies of the system whose
masses or gravity are scaled by 0.5x, 1.0x, ..., 5.0x. At each scale it runs
``episodes`` full episodes from starts drawn uniformly in the system's *operating region*
(``System.operating_region``: a box around the operating point that the nominal LQR recovers
from at every corner), the same seeded starts at every scale, and the impulse test on the scaled
system. Recorded per scale: mean and std of the return, the fraction of episodes *stabilised*
(held the operating point for the system's minimum duration at the end, not terminated:
``System.hold_step``), and the impulse response's metrics.

Why not start at the operating point: mass and g do not move the equilibrium, so from exactly
there any controller with u(a) = u_eq stays put on every scaled system and the sweep could not
fail. From the operating region the controller has to work: at large scales the actuator limit
makes failure physical (the pendulum at 2x g needs 2 N m, its whole limit, to hold 0.2 rad).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np

from leoc.evaluation.rollout import Controller, response_test, rollout
from leoc.systems.base import System
from leoc.systems.perturbations import ParameterError
from leoc.systems.rollout import simulate_settings

SCALE_FACTORS = tuple(np.round(np.arange(0.5, 5.01, 0.5), 2).tolist())
"""The robustness sweep's factors on the mass and on g: 0.5, 1.0, ..., 5.0 (paper figure 8)."""
SCALED_PARAMETERS = ("mass", "gravity")
ROBUSTNESS_EPISODES = 10


class RobustnessPoint(NamedTuple):
    """One scale of one parameter.

    Attributes
    ----------
    parameter : str
        ``mass`` or ``gravity``.
    scale : float
        Factor on the nominal value.
    returns : list of float
        Return of each episode from the operating region.
    stabilised : list of bool
        Whether each episode held the operating point at the end (``System.hold_step``).
    impulse : dict
        Metrics of the impulse response on the scaled system (``ResponseMetrics`` fields).
    """

    parameter: str
    scale: float
    returns: list[float]
    stabilised: list[bool]
    impulse: dict[str, Any]

    @property
    def return_mean(self) -> float:
        """Mean episode return at this scale."""
        return float(np.mean(self.returns))

    @property
    def return_std(self) -> float:
        """Standard deviation of the episode returns at this scale."""
        return float(np.std(self.returns))

    @property
    def fraction_stabilised(self) -> float:
        """Share of the episodes that held the operating point at the end."""
        return float(np.mean(self.stabilised))


class RelevanceTrace(NamedTuple):
    """Main coordinate (report units) and relevance r(x) along a swing-up, per step."""

    time: np.ndarray
    main: np.ndarray
    relevance: np.ndarray


def robustness_starts(system: System, seed: int, episodes: int = ROBUSTNESS_EPISODES) -> np.ndarray:
    """``(episodes, S)`` starts uniform in the system's operating region, from ``seed``."""
    if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes < 1:
        raise ValueError(f"episodes: expected a positive integer, found {episodes!r}")
    return system.sample_operating_region(np.random.default_rng(seed), episodes)


def robustness_sweep(
    system: System,
    controller: Controller,
    seed: int = 0,
    episodes: int = ROBUSTNESS_EPISODES,
    parameters: Sequence[str] = SCALED_PARAMETERS,
    scales: Sequence[float] = SCALE_FACTORS,
) -> list[RobustnessPoint]:
    """Returns, stabilisation and impulse metrics of ``controller`` on every scaled system.

    Parameters
    ----------
    system : System
        The nominal system (its operating region gives the starts).
    controller : callable
        Runs at its own control period.
    seed : int
        Seeds the starts (the same starts at every scale).
    episodes : int
        Episodes per scale.
    parameters, scales
        What is scaled and by how much (``System.with_params``).
    """
    starts = robustness_starts(system, seed, episodes)
    grid = [(parameter, float(scale)) for parameter in parameters for scale in scales]
    # every scale's episodes in one batch, each on its scaled plant (one controller call per
    # decision for all; what simulate on each scaled system gives)
    settings = [(starts, (ParameterError(parameter, scale),)) for parameter, scale in grid]
    batches = simulate_settings(system, controller, settings)
    points = []
    for (parameter, scale), batch in zip(grid, batches, strict=True):
        scaled = system.with_params(**{parameter: scale})
        stabilised = [
            scaled.hold_step(batch.states[i, 1:], terminated=bool(batch.terminated[i])) is not None
            for i in range(len(starts))
        ]
        impulse = response_test(scaled, controller, "impulse").metrics
        points.append(
            RobustnessPoint(
                parameter, scale, batch.total_rewards.tolist(), stabilised, impulse._asdict()
            )
        )
    return points


def relevance_trace(system: System, controller: Controller, seed: int) -> RelevanceTrace | None:
    """Swing-up from the seeded start; None if the controller has no relevance (not hybrid)."""
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
