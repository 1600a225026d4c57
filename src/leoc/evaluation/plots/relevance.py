"""Relevance along a swing-up (the paper's figure 4): the main coordinate and r(x) over time,
systems in rows and hybrid controllers in columns.

The main coordinate is the wrapped deviation from the operating point; the line is broken where
it wraps (a jump of more than half a turn between samples) instead of crossing the panel. Every
panel of a row spans the same time, so an episode that ends early (the cart left its track) is a
short trace ending in a cross.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from leoc.evaluation.plots.common import legend_below, new_figure, pyplot, save_figure

MAIN_COLOUR = "#1f77b4"
RELEVANCE_COLOUR = "#ff7f0e"
HALF_TURN_DEG = 180.0
RELEVANCE_LIMITS = (-0.05, 1.05)
END_MARKER_SIZE = 8
CAPTION = (
    "One swing-up episode of the first seed from the seeded swing-up start. Blue (left axis): "
    "deviation of the main coordinate from the operating point (angles wrapped to +/-180 deg, "
    "the line broken where it wraps); orange (right axis): the relevance r(x) that blends the "
    "LQR (r = 1) with the learned policy (r = 0)."
)


def break_at_wraps(values: np.ndarray, wrapped: bool) -> np.ndarray:
    """``values`` with NaN inserted between samples that jump by more than half a turn (so
    the line stops at a wrap); unchanged for a coordinate that does not wrap."""
    values = np.asarray(values, dtype=float)
    if not wrapped or values.size < 2:
        return values
    jumps = np.flatnonzero(np.abs(np.diff(values)) > HALF_TURN_DEG)
    return np.insert(values, jumps + 1, np.nan)


def _time_with_breaks(time: np.ndarray, values: np.ndarray, wrapped: bool) -> np.ndarray:
    if not wrapped or values.size < 2:
        return time
    jumps = np.flatnonzero(np.abs(np.diff(values)) > HALF_TURN_DEG)
    return np.insert(time, jumps + 1, (time[jumps] + time[jumps + 1]) / 2)


def draw_relevance(
    traces: Mapping[tuple[str, str], Mapping[str, Any]],
    systems: Mapping[str, Any],
    controllers: Sequence[str],
    episode_seconds: Mapping[str, float],
    labels: Mapping[str, str] | None = None,
):
    """The figure of :func:`plot_relevance` (not saved).

    ``traces``: (system, controller) -> ``{"time", "main", "relevance"}``; ``systems``: name ->
    System (for the label and whether the coordinate is an angle); ``episode_seconds``: the
    full episode's duration per system (the x-range of its row).
    """
    plt = pyplot()
    labels = dict(labels or {})
    names = list(systems)
    figure, axes = new_figure(len(names), len(controllers), (4.4, 2.8))
    ended = False
    for row, name in enumerate(names):
        system = systems[name]
        wrapped = bool(system.main_in_degrees)
        for column, controller in enumerate(controllers):
            axis = axes[row][column]
            trace = traces.get((name, controller))
            if trace is None:
                axis.set_axis_off()
                continue
            time = np.asarray(trace["time"], dtype=float)
            main = np.asarray(trace["main"], dtype=float)
            axis.plot(
                _time_with_breaks(time, main, wrapped),
                break_at_wraps(main, wrapped),
                color=MAIN_COLOUR,
            )
            axis.set_xlim(0.0, episode_seconds[name])
            if wrapped:
                axis.set_ylim(-HALF_TURN_DEG * 1.05, HALF_TURN_DEG * 1.05)
            axis.set_xlabel("time [s]")
            axis.set_ylabel(f"deviation of {system.main_label}", color=MAIN_COLOUR)
            twin = axis.twinx()
            twin.plot(time, trace["relevance"], color=RELEVANCE_COLOUR)
            twin.set_ylim(*RELEVANCE_LIMITS)
            twin.set_xlim(0.0, episode_seconds[name])
            twin.set_ylabel("relevance r(x)", color=RELEVANCE_COLOUR)
            if time[-1] < episode_seconds[name] - system.dt * 1.5:
                axis.plot(time[-1], main[-1], marker="X", color="k", markersize=END_MARKER_SIZE)
                ended = True
            axis.set_title(f"{name}: {labels.get(controller, controller)}")
    handles = {}
    if ended:
        handles["episode ended early (left the track)"] = plt.Line2D(
            [], [], color="k", marker="X", linestyle="none"
        )
    legend_below(figure, handles, CAPTION)
    return figure


def plot_relevance(
    traces: Mapping[tuple[str, str], Mapping[str, Any]],
    path: str | Path,
    systems: Mapping[str, Any],
    controllers: Sequence[str],
    episode_seconds: Mapping[str, float],
    labels: Mapping[str, str] | None = None,
) -> Path:
    """Figure 4 as a PNG (see :func:`draw_relevance`)."""
    return save_figure(draw_relevance(traces, systems, controllers, episode_seconds, labels), path)
