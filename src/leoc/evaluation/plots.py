"""Figures: response plots with consistent colours per controller.

matplotlib is imported inside the functions (Agg backend), so importing this module is cheap and
works without a display.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from leoc.evaluation.metrics import DEFAULT_FINAL_WINDOW
from leoc.io import save_figure_atomic
from leoc.systems import make_system

CONTROLLER_COLOURS = {
    "linear": "#222222",
    "linear_pilco": "#8c564b",
    "ddpg_baseline": "#1f77b4",
    "ddpg_hybrid": "#17becf",
    "td3_baseline": "#9467bd",
    "td3_hybrid": "#e377c2",
    "pilco_baseline": "#d62728",
    "pilco_hybrid": "#ff7f0e",
}
CONTROLLER_STYLES = {
    "linear": "-",
    "linear_pilco": "-.",
    "ddpg_hybrid": "--",
    "pilco_hybrid": ":",
    "td3_hybrid": "--",
}
FIGURE_DPI = 120
PANEL_SIZE = (4.2, 3.0)
# Headroom around the range of the stabilising responses, as a fraction of that range.
Y_MARGIN = 0.15


def controller_colour(label: str) -> str:
    """Plot colour of a controller label (grey for labels without one)."""
    return CONTROLLER_COLOURS.get(label, "#7f7f7f")


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(figure, path: str | Path) -> Path:
    """Save ``figure`` to ``path`` atomically and close it."""
    return save_figure_atomic(figure, path, dpi=FIGURE_DPI)


class Response(NamedTuple):
    """One response record to draw: e(t) and whether it stabilised."""

    deviation: np.ndarray
    terminated: bool = False
    settled: bool = True


def _as_response(entry: Any) -> Response:
    if isinstance(entry, Response):
        return entry
    if isinstance(entry, Mapping):
        return Response(
            np.asarray(entry["deviation"], dtype=float),
            bool(entry.get("terminated", False)),
            bool(entry.get("settled", True)),
        )
    return Response(np.asarray(entry, dtype=float))


def stabilising_range(
    records: Sequence[Response], band: float, final_window: int = DEFAULT_FINAL_WINDOW
) -> tuple[float, float] | None:
    """y-range, with a margin, of the records that stabilise: settled, not terminated, and
    ending within ``band`` of the operating point (a pendulum that settles hanging down does not
    count). None if no record does (then the axis scales itself)."""
    good = [
        r.deviation
        for r in records
        if r.settled
        and not r.terminated
        and abs(float(np.mean(r.deviation[-final_window:]))) <= band
    ]
    if not good:
        return None
    low = min(float(np.min(d)) for d in good)
    high = max(float(np.max(d)) for d in good)
    span = max(high - low, 1e-9)
    return low - Y_MARGIN * span, high + Y_MARGIN * span


def _draw_response(axis, time, record: Response, limits, colour, style, label) -> bool:
    """Draw one record clipped to ``limits``; mark clipping and termination. Returns whether
    the record left the range."""
    values = record.deviation
    clipped = False
    if limits is not None:
        clipped = bool(np.any(values < limits[0]) or np.any(values > limits[1]))
        values = np.clip(values, *limits)
    axis.plot(time, values, color=colour, linestyle=style, linewidth=1.2, label=label)
    if clipped:
        outside = np.flatnonzero((record.deviation < limits[0]) | (record.deviation > limits[1]))
        axis.plot(time[outside[0]], values[outside[0]], marker="^", color=colour, markersize=7)
    if record.terminated:
        axis.plot(time[-1], values[-1], marker="X", color=colour, markersize=9)
    return clipped


def plot_responses(
    responses: Mapping[str, Mapping[str, Mapping[str, Sequence[Any]]]],
    path: str | Path,
    labels: Mapping[str, str] | None = None,
) -> Path:
    """Grid of responses: rows = tests (impulse, step), columns = systems.

    Parameters
    ----------
    responses : mapping system -> test -> controller key -> list of records (one per seed)
        A record is an array e(t), a :class:`Response`, or a mapping with ``deviation`` and
        optionally ``terminated``/``settled``.
    path : output PNG path
    labels : mapping controller key -> legend label, optional

    Notes
    -----
    Each panel's y-range is set by the responses that stabilise at the operating point; responses
    that leave it are clipped (a triangle where they leave, "(clipped)" in the legend) and a
    terminated episode ends with a cross, so one diverging controller does not flatten the
    others. The legend sits below the panels, off the data.
    """
    plt = _pyplot()
    labels = dict(labels or {})
    systems = list(responses)
    tests = sorted({test for by_test in responses.values() for test in by_test})
    figure, axes = plt.subplots(
        len(tests),
        len(systems),
        figsize=(PANEL_SIZE[0] * len(systems), PANEL_SIZE[1] * len(tests)),
        squeeze=False,
    )
    handles: dict[str, Any] = {}
    for column, system_name in enumerate(systems):
        system = make_system(system_name)
        for row, test in enumerate(tests):
            axis = axes[row][column]
            by_label = {
                key: [_as_response(entry) for entry in entries]
                for key, entries in responses[system_name].get(test, {}).items()
            }
            limits = stabilising_range(
                [r for records in by_label.values() for r in records], system.hold_band
            )
            for key, records in by_label.items():
                clipped = False
                for record in records:
                    time = np.arange(len(record.deviation)) * system.dt
                    clipped |= _draw_response(
                        axis,
                        time,
                        record,
                        limits,
                        controller_colour(key),
                        CONTROLLER_STYLES.get(key, "-"),
                        None,
                    )
                text = labels.get(key, key) + (" (clipped)" if clipped else "")
                handles.setdefault(
                    text,
                    plt.Line2D(
                        [],
                        [],
                        color=controller_colour(key),
                        linestyle=CONTROLLER_STYLES.get(key, "-"),
                    ),
                )
            if limits is not None:
                axis.set_ylim(*limits)
            axis.axhline(0.0, color="#bbbbbb", linewidth=0.8)
            axis.set_title(f"{system_name}: {test} response")
            axis.set_xlabel("time [s]")
            axis.set_ylabel(f"deviation of {system.main_label}")
    handles["terminated episode"] = plt.Line2D([], [], color="k", marker="X", linestyle="none")
    handles["left the plotted range"] = plt.Line2D([], [], color="k", marker="^", linestyle="none")
    legend_below(figure, handles)
    return save_figure(figure, path)


def axes_handles(axes: Any) -> dict[str, Any]:
    """The legend handles of every axis, one per label (first seen wins)."""
    handles: dict[str, Any] = {}
    for axis in np.ravel(axes):
        for handle, label in zip(*axis.get_legend_handles_labels(), strict=True):
            handles.setdefault(label, handle)
    return handles


def legend_below(figure: Any, handles: Mapping[str, Any]) -> None:
    """One legend for the whole figure, below the panels (off the data)."""
    figure.tight_layout(rect=(0, 0.08, 1, 1))
    if handles:
        figure.legend(
            list(handles.values()),
            list(handles),
            loc="lower center",
            ncol=min(4, len(handles)),
            fontsize="small",
            frameon=False,
        )
