"""What every figure shares: colours and styles per controller, the figure and its legend
below the panels, a caption, atomic saving, and the layout checks the figure tests run.

matplotlib is imported inside the functions (Agg backend), so importing this module is cheap and
works without a display.
"""

from __future__ import annotations

import textwrap
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from leoc.io import save_figure_atomic

#: Line colour of each controller name (hex); other names get a neutral grey.
CONTROLLER_COLOURS = {
    "linear": "#222222",
    "linear_pilco": "#8c564b",
    "ddpg_baseline": "#1f77b4",
    "ddpg_hybrid": "#17becf",
    "ddpg_hybrid_roa": "#2ca02c",
    "ddpg_hybrid_lyapunov": "#8c6d31",
    "sac_baseline": "#393b79",
    "sac_hybrid": "#7b4173",
    "sac_hybrid_roa": "#637939",
    "sac_hybrid_lyapunov": "#ce6dbd",
    "td3_baseline": "#9467bd",
    "td3_hybrid": "#e377c2",
    "td3_hybrid_roa": "#6b6ecf",
    "td3_hybrid_lyapunov": "#e7969c",
    "pilco_baseline": "#d62728",
    "pilco_hybrid": "#ff7f0e",
    "pilco_hybrid_roa": "#bcbd22",
}
#: matplotlib line style of each controller name; other names are drawn solid.
CONTROLLER_STYLES = {
    "linear": "-",
    "linear_pilco": "-.",
    "ddpg_hybrid": "--",
    "ddpg_hybrid_roa": (0, (5, 1, 1, 1)),
    "ddpg_hybrid_lyapunov": (0, (5, 1, 1, 1, 1, 1)),
    "sac_hybrid": "--",
    "sac_hybrid_roa": (0, (5, 1, 1, 1)),
    "sac_hybrid_lyapunov": (0, (5, 1, 1, 1, 1, 1)),
    "pilco_hybrid": ":",
    "pilco_hybrid_roa": (0, (3, 1, 1, 1, 1, 1)),
    "td3_hybrid": "--",
    "td3_hybrid_roa": (0, (5, 1, 1, 1)),
    "td3_hybrid_lyapunov": (0, (5, 1, 1, 1, 1, 1)),
}
CONTROLLER_MARKERS = {
    "linear": "o",
    "linear_pilco": "s",
    "ddpg_baseline": "^",
    "ddpg_hybrid": "v",
    "ddpg_hybrid_roa": "D",
    "ddpg_hybrid_lyapunov": "h",
    "td3_baseline": "H",
    "td3_hybrid": "8",
    "td3_hybrid_roa": "+",
    "td3_hybrid_lyapunov": "x",
    "sac_baseline": "<",
    "sac_hybrid": ">",
    "sac_hybrid_roa": "d",
    "sac_hybrid_lyapunov": "p",
    "pilco_baseline": "P",
    "pilco_hybrid": "X",
    "pilco_hybrid_roa": "*",
}
OTHER_COLOUR = "#7f7f7f"
FIGURE_DPI = 120
PANEL_SIZE = (4.2, 3.0)
LEGEND_COLUMNS = 4
LEGEND_COLUMN_INCHES = 3.0
"""Figure width per legend column: a one-panel figure gets one column, so its legend (its
longest entries are ~2.5 in in the small font) stays within the figure."""
CAPTION_WIDTH_PER_INCH = 16
"""Caption characters per inch of figure width (small font) before it wraps."""
EDGE_TOLERANCE = 1e-9
"""Fraction of an axis span by which drawn data may sit outside its limits (round-off)."""


def controller_colour(label: str) -> str:
    """Colour of the controller called ``label`` (:data:`CONTROLLER_COLOURS`, else grey)."""
    return CONTROLLER_COLOURS.get(label, OTHER_COLOUR)


def controller_style(label: str) -> Any:
    """Line style of the controller called ``label`` (:data:`CONTROLLER_STYLES`, else solid)."""
    return CONTROLLER_STYLES.get(label, "-")


def pyplot():
    """matplotlib.pyplot on the Agg backend (no display needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


_pyplot = pyplot  # the name the report used before the figures moved here


def new_figure(rows: int, columns: int, panel: tuple[float, float] = PANEL_SIZE, **kwargs: Any):
    """A figure of ``rows`` x ``columns`` panels with constrained layout (labels never
    overlap, and a legend placed ``outside`` gets its own room)."""
    plt = pyplot()
    return plt.subplots(
        rows,
        columns,
        figsize=(panel[0] * columns, panel[1] * rows),
        squeeze=False,
        layout="constrained",
        **kwargs,
    )


def save_figure(figure, path: str | Path) -> Path:
    """Save ``figure`` to ``path`` atomically and close it."""
    return save_figure_atomic(figure, path, dpi=FIGURE_DPI)


def axes_handles(axes: Any) -> dict[str, Any]:
    """The legend handles of every axis, one per label (first seen wins)."""
    handles: dict[str, Any] = {}
    for axis in np.ravel(axes):
        for handle, label in zip(*axis.get_legend_handles_labels(), strict=True):
            handles.setdefault(label, handle)
    return handles


def legend_below(figure: Any, handles: Mapping[str, Any], caption: str | None = None) -> None:
    """One legend for the whole figure below the panels, outside them, with the caption as its
    heading, wrapped to the figure's width. The figure grows by the legend's height, so the
    panels keep their size however long the caption (the constrained layout places it)."""
    if not handles and not caption:
        return
    width_inches = figure.get_figwidth()
    width = int(width_inches * CAPTION_WIDTH_PER_INCH)
    columns = min(LEGEND_COLUMNS, len(handles), int(width_inches // LEGEND_COLUMN_INCHES))
    legend = figure.legend(
        list(handles.values()),
        list(handles),
        loc="outside lower center",
        ncol=max(1, columns),
        fontsize="small",
        frameon=False,
        title=textwrap.fill(caption, width) if caption else None,
        title_fontsize="small",
    )
    renderer = figure.canvas.get_renderer()
    height = legend.get_window_extent(renderer).height / figure.dpi
    figure.set_figheight(figure.get_figheight() + height)


# ------------------------------------------------------------------------------------ checks
def _outside(values: np.ndarray, limits: tuple[float, float]) -> bool:
    low, high = sorted(limits)
    slack = EDGE_TOLERANCE * max(high - low, 1e-300)
    finite = values[np.isfinite(values)]
    return bool(finite.size and (finite.min() < low - slack or finite.max() > high + slack))


def _artist_data(artist: Any) -> np.ndarray | None:
    """The data coordinates of a line or filled area, as an (N, 2) array."""
    from matplotlib.collections import Collection
    from matplotlib.lines import Line2D

    if isinstance(artist, Line2D):
        if artist.get_transform() != artist.axes.transData:
            return None  # axhline/axvline: axes coordinates on one side
        x, y = artist.get_xdata(orig=False), artist.get_ydata(orig=False)
        return np.column_stack([np.asarray(x, float), np.asarray(y, float)])
    if isinstance(artist, Collection):
        paths = artist.get_paths()
        if not paths or artist.get_transform() != artist.axes.transData:
            return None
        return np.concatenate([path.vertices for path in paths])
    return None


def data_outside_axes(figure: Any) -> list[str]:
    """Every line or filled area with data beyond its axes' limits (it would be clipped, so
    the reader would not see where it goes)."""
    problems = []
    for axis in figure.axes:
        for artist in [*axis.lines, *axis.collections]:
            data = _artist_data(artist)
            if data is None or not data.size:
                continue
            if _outside(data[:, 0], axis.get_xlim()) or _outside(data[:, 1], axis.get_ylim()):
                problems.append(f"{axis.get_title() or 'panel'}: {artist.get_label()!r} leaves")
    return problems


def _overlaps(first: Any, second: Any) -> bool:
    return first.width > 0 and second.width > 0 and first.overlaps(second)


def legend_overlaps(figure: Any) -> list[str]:
    """Legends that overlap a panel, an axis label, a tick label, a title or another text."""
    figure.canvas.draw()
    renderer = figure.canvas.get_renderer()
    legends = [*figure.legends, *(a.get_legend() for a in figure.axes if a.get_legend())]
    problems = []
    for legend in legends:
        box = legend.get_window_extent(renderer)
        for axis in figure.axes:
            if axis.get_legend() is legend or not axis.get_visible() or not axis.axison:
                continue
            if _overlaps(box, axis.get_tightbbox(renderer)):
                problems.append(f"legend over {axis.get_title() or 'a panel'!r} or its labels")
        for text in figure.texts:
            if text.get_text() and _overlaps(box, text.get_window_extent(renderer)):
                problems.append(f"legend over the text {text.get_text()[:30]!r}")
    return problems


def texts_overlap(figure: Any) -> list[str]:
    """Panels whose labels, ticks or title reach into another panel (a twin axis, drawn over
    its own panel, is not another panel)."""
    figure.canvas.draw()
    renderer = figure.canvas.get_renderer()
    visible = [a for a in figure.axes if a.get_visible() and a.axison]
    problems = []
    for axis in visible:
        for other in visible:
            if other is axis or axis.bbox.bounds == other.bbox.bounds:
                continue
            if _overlaps(axis.get_tightbbox(renderer), other.get_window_extent(renderer)):
                problems.append(f"{axis.get_title()!r} reaches into {other.get_title()!r}")
    return problems


def layout_problems(figure: Any) -> list[str]:
    """Everything the figure tests reject: data beyond the axes, a legend over a panel or a
    label, panels overlapping. Empty for a figure that reads cleanly."""
    return data_outside_axes(figure) + legend_overlaps(figure) + texts_overlap(figure)
