"""Empirical basins beside the certified region of attraction: per system, each controller's
share of the basin box held and of its LQR's certified set held (bars, their values written
upward in a row above 100%, 0 included), and the certified set's own share of the box (a tick
over each controller's bars: each controller's LQR is the one designed for its control
period)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from leoc.evaluation.plots.common import legend_below, new_figure, pyplot, save_figure

BAR_WIDTH = 0.38
BOX_COLOUR = "#1f77b4"
SET_COLOUR = "#2ca02c"
CERTIFIED_COLOUR = "#222222"
PERCENT = 100.0
Y_TOP = 125.0
"""Room above 100% for the bar labels (written upward, so a 3-digit value needs ~20%)."""
MIN_FONT_SIZE = 8.0
"""Smallest font (points) of any text in the figure: 13 pixels at the saved 120 dpi."""
LABEL_FONT_SIZE = MIN_FONT_SIZE
TICK_FONT_SIZE = MIN_FONT_SIZE
LABEL_ROW = 102.0
"""Height (percent) of the row of bar labels: above every bar and every certified tick (both
at most 100%), so no label is crossed by a tick or sits on a neighbouring bar."""
CAPTION = (
    "Blue: share of seeded starts in the basin box from which the controller converges to "
    "the operating point and holds it; green: the same for starts uniform in the certified "
    "region of attraction of the LQR designed for the controller's control period (100% when "
    "the basin contains the certified set); black tick: the certified set's share of the box. "
    "Numbers above the bars: each bar's value in % (n/a: not measured)."
)


def draw_basins(rows: Sequence[Mapping[str, Any]], labels: Mapping[str, str] | None = None):
    """The figure of :func:`plot_basins_summary` (not saved)."""
    plt = pyplot()
    labels = dict(labels or {})
    systems = list(dict.fromkeys(row["system"] for row in rows))
    figure, axes = new_figure(1, len(systems), (4.8, 3.9))
    for axis, system in zip(axes[0], systems, strict=True):
        selected = [row for row in rows if row["system"] == system]
        positions = np.arange(len(selected))
        box = PERCENT * np.array([row["basin_box_fraction"] for row in selected])
        inside = [row["certified_set_held"] for row in selected]
        held = np.array([np.nan if v is None else PERCENT * v for v in inside])
        for offset, values, colour in ((-0.5, box, BOX_COLOUR), (0.5, held, SET_COLOUR)):
            x = positions + offset * BAR_WIDTH
            axis.bar(x, np.nan_to_num(values), BAR_WIDTH, color=colour)
            for xi, value in zip(x, values, strict=True):
                text = "n/a" if np.isnan(value) else f"{value:.0f}"
                axis.text(
                    xi,
                    LABEL_ROW,
                    text,
                    ha="center",
                    va="bottom",
                    rotation=90,  # upright labels of neighbouring bars would run into each other
                    fontsize=LABEL_FONT_SIZE,
                )
        certified = PERCENT * np.array([row["certified_box_fraction"] for row in selected])
        axis.hlines(
            certified,
            positions - BAR_WIDTH,
            positions + BAR_WIDTH,
            colors=CERTIFIED_COLOUR,
            linewidth=1.6,
        )
        axis.set_xticks(positions)
        axis.set_xticklabels(
            [labels.get(row["controller"], row["controller"]) for row in selected],
            rotation=40,
            ha="right",
            fontsize=TICK_FONT_SIZE,
        )
        axis.set_xlim(-0.6, len(selected) - 0.4)
        axis.set_ylim(0.0, Y_TOP)
        axis.set_ylabel("starts held [%]")
        axis.set_title(f"{system}: empirical basins")
    handles = {
        "share of the basin box held": plt.Rectangle((0, 0), 1, 1, color=BOX_COLOUR),
        "share of the certified set held": plt.Rectangle((0, 0), 1, 1, color=SET_COLOUR),
        "certified set's share of the box (LQR at the controller's period)": plt.Line2D(
            [], [], color=CERTIFIED_COLOUR
        ),
    }
    legend_below(figure, handles, CAPTION)
    return figure


def plot_basins_summary(
    rows: Sequence[Mapping[str, Any]], path: str | Path, labels: Mapping[str, str] | None = None
) -> Path:
    """``basins.png`` of the report from its region-of-attraction rows (system, controller,
    ``basin_box_fraction``, ``certified_set_held`` (None: not measured),
    ``certified_box_fraction``)."""
    return save_figure(draw_basins(rows, labels), path)
