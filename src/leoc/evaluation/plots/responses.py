"""Impulse and step responses (the paper's figure 7): one line per controller.

Each panel draws, per controller, the median over seeds of e(t) (the deviation of the main
coordinate from the operating point) with the seeds' range shaded. Angles are unwrapped over
time before the median, so a pendulum that falls over is one trace moving away and not a comb
of wrap lines. The y-range comes from the references (the LQRs and the hybrids that settle); a
trace that leaves it stops at the edge with a triangle, a trace that comes back and settles is
drawn again from where it re-enters, and an episode that ends early (the cart left its track)
ends in a cross.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from leoc.evaluation.metrics import DEFAULT_FINAL_WINDOW
from leoc.evaluation.plots.common import (
    controller_colour,
    controller_style,
    legend_below,
    new_figure,
    pyplot,
    save_figure,
)
from leoc.systems import make_system

Y_MARGIN = 0.15
"""Headroom around the references' range, as a fraction of that range."""
DEGREES_PER_TURN = 360.0
BAND_ALPHA = 0.15
EXIT_MARKER_SIZE = 7
END_MARKER_SIZE = 8
LINE_WIDTH = 1.4


class Response(NamedTuple):
    """One response record to draw: e(t) and whether the run stabilised."""

    deviation: np.ndarray
    terminated: bool = False
    settled: bool = True


class Trace(NamedTuple):
    """A controller's line: its median run over seeds, the seeds' range, and how it ends.

    ``centre`` is the median run's own e(t) (cut short when its episode ended early:
    ``ended_early``); ``low`` and ``high`` the range over the seeds at each step while their
    episodes run (NaN where none does).
    """

    centre: np.ndarray
    low: np.ndarray
    high: np.ndarray
    count: int
    ended_early: bool


class Visible(NamedTuple):
    """The part of a trace drawn inside ``limits``: values with NaN where it is off the panel,
    and the sample (index, edge value) where it first leaves, if it does."""

    values: np.ndarray
    exit: tuple[int, float] | None


def as_response(entry: Any) -> Response:
    """A :class:`Response` from a record, a mapping with ``deviation`` (and optionally
    ``terminated``/``settled``), or a bare array e(t)."""
    if isinstance(entry, Response):
        return entry
    if isinstance(entry, Mapping):
        return Response(
            np.asarray(entry["deviation"], dtype=float),
            bool(entry.get("terminated", False)),
            bool(entry.get("settled", True)),
        )
    return Response(np.asarray(entry, dtype=float))


def is_reference(key: str) -> bool:
    """LQRs and hybrids set the axis range (their responses are the ones the paper compares)."""
    return key.startswith("linear") or "hybrid" in key


def panel_range(by_key: Mapping[str, Sequence[Response]], unwrap: bool) -> tuple[float, float]:
    """y-range of a panel, with a margin, always including 0: the span of the settled, not
    terminated responses of the references; of every controller's when no reference settles;
    of every response (angles within half a turn) when none settles."""
    records = [(key, r) for key, rs in by_key.items() for r in rs]
    candidates = (
        [r for key, r in records if is_reference(key) and r.settled and not r.terminated],
        [r for _, r in records if r.settled and not r.terminated],
        [r for _, r in records],
    )
    chosen = next((group for group in candidates if group), [])
    half_turn = DEGREES_PER_TURN / 2
    values = [
        np.clip(_unwrapped(r.deviation, unwrap), -half_turn, half_turn) if unwrap else r.deviation
        for r in chosen
    ]
    finite = [v[np.isfinite(v)] for v in values if np.isfinite(v).any()]
    low = min([0.0, *(float(v.min()) for v in finite)])
    high = max([0.0, *(float(v.max()) for v in finite)])
    span = max(high - low, 1e-9)
    return low - Y_MARGIN * span, high + Y_MARGIN * span


def _unwrapped(values: np.ndarray, unwrap: bool) -> np.ndarray:
    """Degrees unwrapped over time (a fall is one continuous trace), other units as they are."""
    return np.unwrap(values, period=DEGREES_PER_TURN) if unwrap else values


def median_run(series: Sequence[np.ndarray], limits: tuple[float, float]) -> int:
    """Index of the median run: the one closest to the others (least summed mean absolute
    distance, each trace clipped to ``limits`` and held at its last value once it ended).
    A real trajectory, unlike a point-wise median, which splices pieces of different runs."""
    length = max(len(s) for s in series)
    padded = np.array(
        [np.clip(np.pad(s, (0, length - len(s)), mode="edge"), *limits) for s in series]
    )
    distances = np.abs(padded[:, None, :] - padded[None, :, :]).mean(axis=2).sum(axis=1)
    return int(np.argmin(distances))


def central_trace(records: Sequence[Response], unwrap: bool, limits: tuple[float, float]) -> Trace:
    """The median run (:func:`median_run`) and the range over the seeds, per time step."""
    series = [_unwrapped(r.deviation, unwrap) for r in records]
    length = max(len(s) for s in series)
    matrix = np.full((len(series), length), np.nan)
    for row, values in enumerate(series):
        matrix[row, : len(values)] = values
    running = np.isfinite(matrix).any(axis=0)
    low, high = np.full(length, np.nan), np.full(length, np.nan)
    low[running] = np.nanmin(matrix[:, running], axis=0)
    high[running] = np.nanmax(matrix[:, running], axis=0)
    chosen = median_run(series, limits)
    return Trace(
        centre=series[chosen],
        low=low,
        high=high,
        count=len(series),
        ended_early=bool(records[chosen].terminated),
    )


def visible_part(
    values: np.ndarray, limits: tuple[float, float], tail: int = DEFAULT_FINAL_WINDOW
) -> Visible:
    """What of ``values`` is drawn inside ``limits``: everything up to where it first leaves
    (that sample clamped to the edge, so the line reaches it), and, when it comes back and stays
    inside for at least ``tail`` final samples, from its last re-entry to the end."""
    low, high = limits
    inside = (values >= low) & (values <= high)
    if inside.all():
        return Visible(values.copy(), None)
    first_out = int(np.argmin(inside))
    drawn = np.full(values.shape, np.nan)
    drawn[:first_out] = values[:first_out]
    edge = high if values[first_out] > high else low
    drawn[first_out] = edge
    outside = np.flatnonzero(~inside)
    back = int(outside[-1]) + 1
    if len(values) - back >= tail:
        drawn[back:] = values[back:]
    return Visible(drawn, (first_out, edge))


def _band_centre(trace: Trace) -> np.ndarray:
    """A series that leaves the plotted range exactly when the seeds' range does."""
    low, high = trace.low, trace.high
    return np.where(np.isfinite(low), np.where(np.abs(low) > np.abs(high), low, high), np.inf)


def _draw_trace(axis, time, trace: Trace, limits, key: str, bands: bool) -> set[str]:
    """Draw one controller's trace (and band); returns the markers used."""
    colour, style = controller_colour(key), controller_style(key)
    centre = trace.centre
    visible = visible_part(centre, limits)
    steps = np.arange(len(centre))
    axis.plot(time[steps], visible.values, color=colour, linestyle=style, linewidth=LINE_WIDTH)
    used = set()
    if bands and trace.count > 1:
        # the seeds' range while every seed's episode runs inside the plotted range, and again
        # over a final stretch where they all settle back inside (no slivers in between)
        inside = np.isfinite(visible_part(_band_centre(trace), limits).values)
        inside &= (trace.low >= limits[0]) & (trace.high <= limits[1])
        if inside.any():
            axis.fill_between(
                time[: len(inside)],
                np.where(inside, trace.low, np.nan),
                np.where(inside, trace.high, np.nan),
                color=colour,
                alpha=BAND_ALPHA,
                linewidth=0,
            )
            used.add("band")
    if visible.exit is not None:
        index, edge = visible.exit
        marker = "^" if edge == limits[1] else "v"
        axis.plot(time[index], edge, marker=marker, color=colour, markersize=EXIT_MARKER_SIZE)
        used.add("exit")
    if trace.ended_early and np.isfinite(visible.values[-1]):
        axis.plot(
            time[len(centre) - 1],
            visible.values[-1],
            marker="X",
            color=colour,
            markersize=END_MARKER_SIZE,
            linestyle="none",
        )
        used.add("terminated")
    return used


def response_caption(
    counts: set[int], markers: set[str], angles: bool = True, controllers: int = 2
) -> str:
    """The figure's caption: what the line, the band and the markers are (``angles``: some
    panel shows an angle; ``controllers``: how many controllers the figure draws)."""
    several = sorted(n for n in counts if n > 1)
    if not several:
        what = "Line: e(t), the deviation of the main coordinate from the operating point"
    else:
        seeds = "/".join(str(n) for n in several)
        single = "; one run where a controller has one, as the LQRs" if 1 in counts else ""
        what = (
            f"Line: the median run over the {seeds} seeds (the run closest to the others"
            f"{single}) of e(t), the deviation of the main coordinate from the operating point"
        )
    parts = [what + (" (angles unwrapped over time, so a fall is one trace)." if angles else ".")]
    if controllers > 1:
        parts.append("The y-range covers the LQRs and the hybrids that settle.")
    if "band" in markers:
        parts.append("Shaded: the range over the seeds, where all of them are in the plot.")
    if "exit" in markers:
        parts.append("A triangle: the trace leaves the range there (it falls or diverges).")
    if "terminated" in markers:
        parts.append("A cross: the episode ended early (the cart left its track).")
    return " ".join(parts)


def draw_responses(
    responses: Mapping[str, Mapping[str, Mapping[str, Sequence[Any]]]],
    labels: Mapping[str, str] | None = None,
    bands: bool = True,
):
    """The figure of :func:`plot_responses` (not saved): rows = tests, columns = systems."""
    plt = pyplot()
    labels = dict(labels or {})
    systems = list(responses)
    tests = sorted({test for by_test in responses.values() for test in by_test})
    figure, axes = new_figure(len(tests), len(systems))
    handles: dict[str, Any] = {}
    markers: set[str] = set()
    counts: set[int] = set()
    for column, system_name in enumerate(systems):
        system = make_system(system_name)
        unwrap = bool(system.main_in_degrees)
        for row, test in enumerate(tests):
            axis = axes[row][column]
            by_key = {
                key: [as_response(entry) for entry in entries]
                for key, entries in responses[system_name].get(test, {}).items()
            }
            limits = panel_range(by_key, unwrap)
            length = max((len(r.deviation) for rs in by_key.values() for r in rs), default=1)
            time = np.arange(length) * system.dt
            for key, records in by_key.items():
                if not records:
                    continue
                trace = central_trace(records, unwrap, limits)
                counts.add(trace.count)
                markers |= _draw_trace(axis, time, trace, limits, key, bands)
                handles.setdefault(
                    labels.get(key, key),
                    plt.Line2D(
                        [], [], color=controller_colour(key), linestyle=controller_style(key)
                    ),
                )
            axis.set_ylim(*limits)
            axis.set_xlim(0.0, time[-1])
            axis.axhline(0.0, color="#bbbbbb", linewidth=0.8, zorder=0)
            axis.set_title(f"{system_name}: {test} response")
            axis.set_xlabel("time [s]")
            axis.set_ylabel(f"deviation of {system.main_label}")
    order = list(labels.values())
    handles = dict(
        sorted(
            handles.items(),
            key=lambda item: order.index(item[0]) if item[0] in order else len(order),
        )
    )
    if "exit" in markers:
        handles["left the plotted range"] = plt.Line2D(
            [], [], color="k", marker="^", linestyle="none"
        )
    if "terminated" in markers:
        handles["episode ended early"] = plt.Line2D([], [], color="k", marker="X", linestyle="none")
    angles = any(make_system(name).main_in_degrees for name in systems)
    keys = {key for by_test in responses.values() for t in by_test.values() for key in t}
    legend_below(figure, handles, response_caption(counts, markers, angles, len(keys)))
    return figure


def plot_responses(
    responses: Mapping[str, Mapping[str, Mapping[str, Sequence[Any]]]],
    path: str | Path,
    labels: Mapping[str, str] | None = None,
) -> Path:
    """Grid of responses: rows = tests (impulse, step), columns = systems; saved as a PNG.

    Parameters
    ----------
    responses : mapping system -> test -> controller key -> list of records (one per seed)
        A record is an array e(t), a :class:`Response`, or a mapping with ``deviation`` and
        optionally ``terminated``/``settled``.
    path : output PNG path
    labels : mapping controller key -> legend label, optional

    Notes
    -----
    One line per controller: the median over seeds, the seeds' range shaded (see the module
    docstring for the range, the triangles and the crosses). One legend below the panels, one
    entry per controller, then a caption that says what the line, band and markers are.
    """
    return save_figure(draw_responses(responses, labels), path)
