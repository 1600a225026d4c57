"""Robustness (the paper's figure 8): fraction of episodes stabilised and mean return against
the scale of each physical parameter, one line per controller.

Curves that coincide (several controllers failing at the same scales) stay visible: each
controller has its own marker and line style, drawn thinner the later it comes, and its points
are nudged sideways by a small, fixed offset.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from leoc.evaluation.plots.common import (
    CONTROLLER_MARKERS,
    axes_handles,
    controller_colour,
    controller_style,
    legend_below,
    new_figure,
    save_figure,
)

QUANTITIES = ("fraction_stabilised", "return_mean")
Y_LABELS = {
    "fraction_stabilised": "episodes stabilised [%]",
    "return_mean": "mean episode return",
}
DODGE = 0.025
"""Sideways offset between consecutive controllers, in units of the scale."""
WIDEST_LINE = 2.6
NARROWEST_LINE = 0.9
PERCENT = 100.0
FRACTION_LIMITS = (-5.0, 105.0)


def robustness_caption(episodes: int | None) -> str:
    """What each point is."""
    per_point = f"{episodes} episodes" if episodes else "the episodes"
    return (
        "Each controller, trained on the nominal system, runs on systems whose mass or gravity "
        f"is scaled; each point aggregates {per_point} (all seeds) started in the operating "
        "region: the share that ends holding the operating point, and their mean return. "
        "Points are nudged sideways per controller so coinciding curves stay visible."
    )


def draw_robustness(
    rows: Sequence[Mapping[str, Any]],
    controllers: Sequence[str],
    parameters: Sequence[str],
    labels: Mapping[str, str] | None = None,
):
    """The figure of :func:`plot_robustness` (not saved): rows = parameter x quantity,
    columns = systems."""
    labels = dict(labels or {})
    systems = list(dict.fromkeys(row["system"] for row in rows))
    panels = [(p, q) for p in parameters for q in QUANTITIES]
    figure, axes = new_figure(len(panels), max(1, len(systems)), (4.2, 2.6))
    present = [c for c in controllers if any(r["controller"] == c for r in rows)]
    widths = np.linspace(WIDEST_LINE, NARROWEST_LINE, max(1, len(present)))
    offsets = (np.arange(len(present)) - (len(present) - 1) / 2) * DODGE
    for column, system in enumerate(systems):
        for panel, (parameter, quantity) in enumerate(panels):
            axis = axes[panel][column]
            for index, controller in enumerate(present):
                selected = [
                    r
                    for r in rows
                    if (r["system"], r["parameter"], r["controller"])
                    == (system, parameter, controller)
                ]
                if not selected:
                    continue
                scale = np.array([r["scale"] for r in selected]) + offsets[index]
                values = np.array([r[quantity] for r in selected], dtype=float)
                if quantity == "fraction_stabilised":
                    values = PERCENT * values
                axis.plot(
                    scale,
                    values,
                    color=controller_colour(controller),
                    linestyle=controller_style(controller),
                    linewidth=widths[index],
                    marker=CONTROLLER_MARKERS.get(controller, "o"),
                    markersize=4,
                    markerfacecolor="none",
                    label=labels.get(controller, controller),
                )
            axis.set_title(f"{system}: {parameter} scaled")
            axis.set_xlabel(f"{parameter} / nominal {parameter}")
            axis.set_ylabel(Y_LABELS[quantity])
            if quantity == "fraction_stabilised":
                axis.set_ylim(*FRACTION_LIMITS)
    episodes = {int(r.get("n_episodes", 0)) for r in rows}
    caption = robustness_caption(episodes.pop() if len(episodes) == 1 else None)
    legend_below(figure, axes_handles(axes), caption)
    return figure


def plot_robustness(
    rows: Sequence[Mapping[str, Any]],
    path: str | Path,
    controllers: Sequence[str],
    parameters: Sequence[str],
    labels: Mapping[str, str] | None = None,
) -> Path:
    """Figure 8: fraction stabilised and return against the scale, per parameter.

    ``rows``: the report's robustness rows (system, controller, parameter, scale,
    ``fraction_stabilised``, ``return_mean``, ``n_episodes``); ``controllers``: their drawing
    order; ``parameters``: the scaled parameters, one pair of panel rows each.
    """
    return save_figure(draw_robustness(rows, controllers, parameters, labels), path)
