"""The DDPG ablation's figure: success rate against training budget, one line per setting,
one panel per system (columns) and controller (rows)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from leoc.evaluation.plots.common import (
    OTHER_COLOUR,
    axes_handles,
    legend_below,
    new_figure,
    save_figure,
)

#: Colour of each ablation setting (:data:`leoc.experiments.ablation.ALL_SETTINGS`).
SETTING_COLOURS = {
    "leoc": "#222222",
    "authors": "#d62728",
    "exploration": "#1f77b4",
    "initial_collect": "#ff7f0e",
    "critic": "#2ca02c",
    "exit_penalty": "#9467bd",
    "model_selection": "#8c564b",
    "all_factors": "#17becf",
    "horizon_exit": "#e377c2",
    "defaults": "#bcbd22",
    "sac_sb3_critic": "#7f7f7f",
    "sac_alpha_0.1": "#393b79",
    "sac_alpha_0.01": "#ad494a",
    "sac_initial_collect": "#8c6d31",
    "sac_ddpg_optimiser": "#7b4173",
    "sac_huber": "#98df8a",
    "sac_critic": "#2ca02c",
    "sac_ou": "#1f77b4",
}
# "all but X" takes X's colour, dash-dotted.
SETTING_COLOURS.update(
    {
        f"all_but_{name}": SETTING_COLOURS[name]
        for name in ("exploration", "initial_collect", "critic", "exit_penalty", "model_selection")
    }
)
# all_safe_exit: the exit rule's colour, dotted (it keeps half of that rule); all_horizon_exit:
# the horizon exit's colour, dotted.
SETTING_COLOURS["all_safe_exit"] = SETTING_COLOURS["exit_penalty"]
SETTING_COLOURS["all_horizon_exit"] = SETTING_COLOURS["horizon_exit"]
# The reference settings are drawn thicker (leoc and the defaults solid, the authors' dashed).
SETTING_STYLES = {
    "authors": "--",
    **{name: "-." for name in SETTING_COLOURS if name.startswith("all_but_")},
    "all_safe_exit": ":",
    "all_horizon_exit": ":",
}
REFERENCE_WIDTH = 2.2
LINE_WIDTH = 1.3
MARKERS_PER_LINE = 10
"""About how many markers each line gets (one per evaluated budget would crowd it)."""
DODGE = 0.012
"""Vertical offset between consecutive settings' lines (fraction of seeds), so that lines at
the same rate stay visible; the caption says so."""
Y_MARGIN = 0.08
STEPS_PER_UNIT = 1000.0
PANEL = (4.2, 2.9)


def _dodge(index: int, count: int) -> float:
    return (index - (count - 1) / 2.0) * DODGE


def draw_success_vs_budget(
    curves: Mapping[str, Mapping[str, Mapping[str, Mapping[str, Sequence[float]]]]],
    paper_budgets: Mapping[str, int],
    setting_labels: Mapping[str, str] | None = None,
    controller_labels: Mapping[str, str] | None = None,
    caption: str | None = None,
):
    """The figure of :func:`plot_success_vs_budget` (not saved)."""
    setting_labels = dict(setting_labels or {})
    controller_labels = dict(controller_labels or {})
    systems = list(curves)
    controllers = list(dict.fromkeys(c for system in systems for c in curves[system]))
    settings = list(
        dict.fromkeys(s for system in systems for c in curves[system] for s in curves[system][c])
    )
    figure, axes = new_figure(max(1, len(controllers)), max(1, len(systems)), PANEL)
    for column, system in enumerate(systems):
        for row, controller in enumerate(controllers):
            axis = axes[row][column]
            lines = curves[system].get(controller, {})
            for index, setting in enumerate(settings):
                if setting not in lines:
                    continue
                budgets = np.asarray(lines[setting]["budgets"], float) / STEPS_PER_UNIT
                rates = np.asarray(lines[setting]["rates"], float) + _dodge(index, len(settings))
                reference = setting in ("leoc", "authors", "defaults")
                axis.plot(
                    budgets,
                    rates,
                    color=SETTING_COLOURS.get(setting, OTHER_COLOUR),
                    linestyle=SETTING_STYLES.get(setting, "-"),
                    linewidth=REFERENCE_WIDTH if reference else LINE_WIDTH,
                    marker="o" if not reference else None,
                    markersize=3,
                    markevery=max(1, len(budgets) // MARKERS_PER_LINE),
                    label=setting_labels.get(setting, setting),
                )
            if system in paper_budgets:
                axis.axvline(
                    paper_budgets[system] / STEPS_PER_UNIT,
                    color="#999999",
                    linestyle=":",
                    linewidth=1.0,
                    label="the paper's budget",
                )
            spread = abs(_dodge(0, len(settings)))  # the widest offset of a line
            axis.set_ylim(-Y_MARGIN - spread, 1.0 + Y_MARGIN + spread)
            axis.set_xlim(left=0.0)
            axis.set_title(f"{system}: {controller_labels.get(controller, controller)}")
            axis.set_xlabel("training budget [1000 environment steps]")
            axis.set_ylabel("success rate [fraction of seeds]")
            axis.grid(True, alpha=0.3)
    legend_below(figure, axes_handles(axes), caption)
    return figure


def plot_success_vs_budget(
    curves: Mapping[str, Mapping[str, Mapping[str, Mapping[str, Sequence[float]]]]],
    path: str | Path,
    paper_budgets: Mapping[str, int],
    setting_labels: Mapping[str, str] | None = None,
    controller_labels: Mapping[str, str] | None = None,
    caption: str | None = None,
) -> Path:
    """Success rate against training budget: one panel per system (column) and controller
    (row), one line per ablation setting, the paper's budget a grey vertical line.

    Parameters
    ----------
    curves : mapping
        ``system -> controller -> setting -> {"budgets": [...], "rates": [...]}``: environment
        steps, and the fraction of seeds that succeeded at each.
    path : path
        PNG file to write (atomically).
    paper_budgets : mapping system -> int
        Where the grey vertical line goes (environment steps).
    setting_labels, controller_labels : mapping, optional
        Legend and title texts (default: the names).
    caption : str, optional
        Heading of the legend below the panels.

    Returns
    -------
    Path
    """
    figure: Any = draw_success_vs_budget(
        curves, paper_budgets, setting_labels, controller_labels, caption
    )
    return save_figure(figure, path)
