"""Empirical basins beside the certified region of attraction.

The report's summary (:func:`plot_basins_summary`): per system, each controller's share of the
basin box held and of its LQR's certified set held (bars, their values written upward in a row
above 100%, 0 included), and the certified set's own share of the box (a tick over each
controller's bars: each controller's LQR is the one designed for its control period).

``leoc roa --plot`` (:func:`plot_basins`): one panel per controller, its basin on a 2-D slice
through the operating point with the certified set's slice over it.
"""

from __future__ import annotations

import math
import textwrap
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from leoc.control.roa import LyapunovCertificate
from leoc.evaluation.basins import Basin
from leoc.evaluation.plots.common import legend_below, new_figure, pyplot, save_figure
from leoc.systems.base import System

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
PANEL_SIZE = (4.8, 3.9)
"""Size (inches) of a panel of up to :data:`PANEL_CONTROLLERS` controllers."""
PANEL_CONTROLLERS = 11
"""Controllers whose bar labels fit apart in a panel :data:`PANEL_SIZE` wide (the reproduce
controllers before the Lyapunov hybrids); a panel of more is widened in proportion."""
ELLIPSE_POINTS = 400
"""Points on the boundary of the certified set's slice."""
BASIN_COLOURS = ("#d9d9d9", "#74c476")
"""Slice cells whose start does not / does converge and hold."""
CAPTION_CHARS_PER_INCH = 15
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
    most = max((sum(row["system"] == s for row in rows) for s in systems), default=1)
    width = PANEL_SIZE[0] * max(1.0, most / PANEL_CONTROLLERS)
    figure, axes = new_figure(1, len(systems), (width, PANEL_SIZE[1]))
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


def _ellipse_boundary(P: np.ndarray, rho: float, dims: tuple[int, int], points: int) -> np.ndarray:
    """Boundary (points, 2) of the slice ``{z : z^T P z <= rho, z_k = 0 for k not in dims}``."""
    sub = P[np.ix_(dims, dims)]
    angles = np.linspace(0.0, 2.0 * math.pi, points)
    circle = np.stack([np.cos(angles), np.sin(angles)])
    return (math.sqrt(rho) * np.linalg.solve(np.linalg.cholesky(sub).T, circle)).T


def plot_basins(
    system: System,
    certificate: LyapunovCertificate,
    basins: Mapping[str, Basin],
    dims: tuple[int, int],
    points: int,
    path: str | Path,
    box: np.ndarray | None = None,
) -> Path:
    """:func:`draw_basin_slices` saved as a PNG at ``path``; returns the path."""
    from leoc.io import save_figure_atomic

    figure = draw_basin_slices(system, certificate, basins, dims, points, box)
    return save_figure_atomic(figure, Path(path))


def draw_basin_slices(
    system: System,
    certificate: LyapunovCertificate,
    basins: Mapping[str, Basin],
    dims: tuple[int, int],
    points: int,
    box: np.ndarray | None = None,
) -> Any:
    """One panel per controller: the basin on a 2-D slice through the operating point
    (:func:`leoc.evaluation.basins.slice_grid` with the same ``dims`` and ``points``), the
    certified set's slice over it and, when given, the basin ``box``'s slice (the box the
    command's percentages refer to). Axes in state units; each panel's title gives the share of
    *this slice* held. Returns the matplotlib figure."""
    plt = pyplot()
    count = len(basins)
    fig, axes = plt.subplots(
        1, count, figsize=(4.6 * max(count, 2), 4.4), squeeze=False, layout="constrained"
    )
    boundary = _ellipse_boundary(certificate.P, certificate.rho, dims, ELLIPSE_POINTS)
    for axis, (label, basin) in zip(axes[0], basins.items(), strict=True):
        if basin.starts.shape[0] != points * points:
            raise ValueError(
                f"basins[{label!r}]: expected {points}x{points} slice starts, found "
                f"{basin.starts.shape[0]}"
            )
        _draw_slice(axis, system, certificate, label, basin, dims, points, boundary, box)
    _slice_legend(fig, system, certificate, dims, box)
    return fig


def _draw_slice(
    axis: Any,
    system: System,
    certificate: LyapunovCertificate,
    label: str,
    basin: Basin,
    dims: tuple[int, int],
    points: int,
    boundary: np.ndarray,
    box: np.ndarray | None,
) -> None:
    """One panel of :func:`draw_basin_slices`."""
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Rectangle

    from leoc.systems.units import state_axis_label

    first, second = dims
    centre = certificate.operating_state
    grid_a = basin.starts[:, first].reshape(points, points)
    grid_b = basin.starts[:, second].reshape(points, points)
    held = basin.held.reshape(points, points).astype(float)
    axis.pcolormesh(
        grid_a,
        grid_b,
        held,
        cmap=ListedColormap(BASIN_COLOURS),
        vmin=0.0,
        vmax=1.0,
        shading="nearest",
    )
    axis.plot(centre[first] + boundary[:, 0], centre[second] + boundary[:, 1], "k-", lw=1.5)
    if box is not None:
        axis.add_patch(
            Rectangle(
                (centre[first] - box[first], centre[second] - box[second]),
                2 * box[first],
                2 * box[second],
                fill=False,
                edgecolor=BOX_COLOUR,
                linestyle="--",
                linewidth=1.2,
            )
        )
    axis.set_title(f"{label}: {basin.fraction:.0%} of this slice held")
    axis.set_xlabel(state_axis_label(system, first))
    axis.set_ylabel(state_axis_label(system, second))


def _slice_legend(
    fig: Any,
    system: System,
    certificate: LyapunovCertificate,
    dims: tuple[int, int],
    box: np.ndarray | None,
) -> None:
    """The legend of :func:`draw_basin_slices` below its panels, the caption as its title."""
    from matplotlib.patches import Patch

    plt = pyplot()
    first, second = dims
    handles = [
        Patch(color=BASIN_COLOURS[1], label="converges and holds"),
        Patch(color=BASIN_COLOURS[0], label="does not"),
        plt.Line2D([], [], color="k", label=f"{certificate.basis} set V <= {certificate.rho:.3g}"),
    ]
    if box is not None:
        handles.append(plt.Line2D([], [], color=BOX_COLOUR, ls="--", label="basin box"))
    others = [n for k, n in enumerate(system.state_names) if k not in dims]
    caption = (
        f"{system.name}: starts on the {system.state_names[first]}-"
        f"{system.state_names[second]} plane through the operating point"
        + (f" ({', '.join(others)} at the operating point)" if others else "")
        + "; the command's percentages of the box count starts drawn in the whole basin box."
    )
    fig.legend(
        handles=handles,
        loc="outside lower center",
        ncol=len(handles),
        fontsize="small",
        frameon=False,
        title=textwrap.fill(caption, int(fig.get_figwidth() * CAPTION_CHARS_PER_INCH)),
        title_fontsize="small",
    )
