"""Figures, one module per family: responses (paper figure 7), learning curves (figure 6),
robustness (figure 8), relevance along a swing-up (figure 4), empirical basins; shared colours,
legend, caption and the layout checks in ``leoc.evaluation.plots.common``.

matplotlib is imported inside the functions (Agg backend), so importing these modules is cheap
and works without a display.
"""

from leoc.evaluation.plots.common import (
    CONTROLLER_COLOURS,
    CONTROLLER_STYLES,
    axes_handles,
    controller_colour,
    layout_problems,
    legend_below,
    save_figure,
)
from leoc.evaluation.plots.responses import Response, draw_responses, plot_responses

__all__ = [
    "CONTROLLER_COLOURS",
    "CONTROLLER_STYLES",
    "Response",
    "axes_handles",
    "controller_colour",
    "draw_responses",
    "layout_problems",
    "legend_below",
    "plot_responses",
    "save_figure",
]
