r"""The two metric sets of a response test: leoc's own and the authors'.

A :class:`MetricSet` names how a recorded trajectory becomes the deviation signal :math:`e(t)`
and which metrics are computed on it; it is chosen at the edge (``--metrics``) and passed down
as an object.

* ``leoc`` (default): the main coordinate wrapped to :math:`[-180, 180)` degrees (positions as
  is), :func:`~leoc.evaluation.metrics.response_metrics` with a band of 2 % of the peak error.
* ``authors``: nrjc/LEOC ``plotting/plotter.py``: :math:`\arcsin(\sin\theta)` in degrees
  (which folds an angle past 90 degrees back), positions as is,
  :func:`~leoc.evaluation.metrics.authors_response_metrics` (last sample, absolute band
  :math:`\pi/180`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from leoc.evaluation.metrics import ResponseMetrics, authors_response_metrics, response_metrics
from leoc.systems.base import System

__all__ = ["METRIC_SETS", "MetricSet", "get_metric_set"]


def _arcsin_deviation(system: System, states: np.ndarray) -> np.ndarray:
    """The authors' e(t): ``degrees(arcsin(sin(theta - a)))`` for an angle, else ``x - a``."""
    states = np.asarray(states, dtype=float)
    index = system.main_index
    deviation = states[..., index] - float(system.operating_state[index])
    if index in system.angle_indices:
        deviation = np.arcsin(np.sin(deviation))
    return np.degrees(deviation) if system.main_in_degrees else deviation


def _leoc_deviation(system: System, states: np.ndarray) -> np.ndarray:
    return system.main_coordinate(states)


def _leoc_metrics(
    e: np.ndarray, band: float | None, dt: float, terminated: bool
) -> ResponseMetrics:
    return response_metrics(e, band, dt=dt, terminated=terminated)


def _authors_metrics(
    e: np.ndarray, band: float | None, dt: float, terminated: bool
) -> ResponseMetrics:
    if band is not None:
        raise ValueError(f"band: the authors' metric set has its own band (pi/180), found {band}")
    return authors_response_metrics(e, dt=dt, terminated=terminated)


class MetricSet(NamedTuple):
    """How a response record is measured.

    Attributes
    ----------
    name : str
    deviation : callable
        ``deviation(system, states (T, S)) -> e (T,)`` in report units.
    metrics : callable
        ``metrics(e, band, dt, terminated) -> ResponseMetrics``; ``band`` None for the set's
        default.
    description : str
        One line for reports.
    """

    name: str
    deviation: Callable[[System, np.ndarray], np.ndarray]
    metrics: Callable[[np.ndarray, float | None, float, bool], ResponseMetrics]
    description: str


#: The metric sets by name (``--metrics``): leoc's and the authors'.
METRIC_SETS: dict[str, MetricSet] = {
    "leoc": MetricSet(
        "leoc",
        _leoc_deviation,
        _leoc_metrics,
        "wrapped angle; final value = mean of the last 20 samples; settling band 2% of the peak",
    ),
    "authors": MetricSet(
        "authors",
        _arcsin_deviation,
        _authors_metrics,
        "arcsin(sin theta); steady state = last sample; overshoot = peak deviation from it; "
        "settling band +/- pi/180 (T when the record never leaves it)",
    ),
}


def get_metric_set(name: str | MetricSet) -> MetricSet:
    """The metric set called ``name`` (a :class:`MetricSet` is returned as is)."""
    if isinstance(name, MetricSet):
        return name
    if name not in METRIC_SETS:
        raise ValueError(f"metrics: expected one of {tuple(METRIC_SETS)}, found {name!r}")
    return METRIC_SETS[name]
