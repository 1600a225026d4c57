"""Impulse and step response tests on the one closed-loop simulation.

A *controller* is any callable mapping a float64 observation batch ``(B, O)`` to physical
actions ``(B, A)`` (a torch module such as :class:`~leoc.policies.HybridPolicy`); it runs at its
own control period (``action_repeat``, see :mod:`leoc.systems.rollout`, which also records r(x)
of hybrids). :func:`rollout`, :class:`Trajectory` and the hold test are re-exported from there:
one rollout serves evaluation, PILCO data collection, DDPG evaluation and the basins.
"""

from __future__ import annotations

from typing import Literal, NamedTuple

import numpy as np

from leoc.evaluation.metric_sets import MetricSet, get_metric_set
from leoc.evaluation.metrics import ResponseMetrics
from leoc.systems.base import System
from leoc.systems.rollout import (
    Controller,
    Trajectory,
    control_period,
    hold_step,
    holds,
    relevance_function,
    rollout,
    simulate,
)

__all__ = [
    "IMPULSE_MAGNITUDE",
    "RESPONSE_STEPS",
    "RESPONSE_TESTS",
    "STEP_MAGNITUDE",
    "Controller",
    "ResponseResult",
    "Trajectory",
    "control_period",
    "hold_step",
    "holds",
    "measure_response",
    "relevance_function",
    "response_offsets",
    "response_test",
    "rollout",
    "simulate",
]

#: The response tests: an impulse or a step on the action.
RESPONSE_TESTS = ("impulse", "step")
ResponseTest = Literal["impulse", "step"]
#: Impulse test: added to the action of the first simulator step only.
IMPULSE_MAGNITUDE = -1.0
#: Step test: added to every action.
STEP_MAGNITUDE = -0.2
#: Length of a response test in simulator steps.
RESPONSE_STEPS = 200


class ResponseResult(NamedTuple):
    """An impulse or step response: the trajectory, the main-coordinate deviation e(t) in
    report units (degrees or metres), and its metrics."""

    test: str
    trajectory: Trajectory
    deviation: np.ndarray
    metrics: ResponseMetrics


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
    band: float | None = None,
    metric_set: str | MetricSet = "leoc",
) -> ResponseResult:
    """Impulse or step response from the operating point, with its metrics.

    The system starts exactly at its operating point; ``impulse`` adds -1.0 to the action of the
    first simulator step, ``step`` adds -0.2 to every action, for ``steps`` simulator steps; the
    controller runs at its own control period. The deviation e(t) is the main coordinate
    (degrees for pendulum and cart-pole, metres for mountain car), ``steps + 1`` samples from
    t = 0 (fewer if the episode terminated), as the ``metric_set`` computes it
    (:mod:`leoc.evaluation.metric_sets`: leoc's wrapped angle, or the authors'
    arcsin(sin theta)). Metrics: leoc's, settling band 2 % of the peak error by default or the
    absolute ``band`` (e.g. ``system.settling_band``); or the authors' (``band`` must be None).
    """
    measure = get_metric_set(metric_set)  # an unknown set fails before the simulation
    offsets = response_offsets(test, steps, system.action_dim)
    trajectory = rollout(system, controller, system.operating_state, steps, offsets)
    return measure_response(system, trajectory, test, band, measure)


def measure_response(
    system: System,
    trajectory: Trajectory,
    test: ResponseTest,
    band: float | None = None,
    metric_set: str | MetricSet = "leoc",
) -> ResponseResult:
    """The deviation and metrics of a response ``trajectory`` simulated by
    :func:`response_test`, as ``metric_set`` computes them: one simulation measured with
    several metric sets."""
    measure = get_metric_set(metric_set)
    deviation = measure.deviation(system, trajectory.states)
    metrics = measure.metrics(deviation, band, system.dt, trajectory.terminated)
    return ResponseResult(test, trajectory, deviation, metrics)
