"""Impulse and step responses (the paper's figure 7): one line per controller.

Each panel draws, per controller, the median over seeds of e(t) (the deviation of the main
coordinate from the operating point) with the seeds' range shaded. Angles are unwrapped over
time before the median, so a pendulum that falls over is one trace moving away and not a comb
of wrap lines.

Two decisions are made from the records, not from the drawing (:func:`panel_layout`):

- the y-range (:func:`panel_range`) covers the runs that settle (not terminated), less the
  outliers among them (a peak over :data:`OUTLIER_FACTOR` times their median peak), so one
  run that settles far away does not flatten the others;
- a trace *falls or diverges* (:func:`falls_or_diverges`) when its episode ended early, or
  when it did not settle and its final window reaches beyond the system's hold band.

A trace that leaves the y-range stops at the edge with a triangle, filled when it falls or
diverges and open when it does not (it settles or stays near the operating point out of the
range), and the edge is annotated with how far it went ("min -4.15 m"); a trace that comes back
and settles is drawn again from where it re-enters, and an episode that ends early (the cart
left its track) ends in a cross.
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
"""Headroom around the settled runs' range, as a fraction of that range."""
OUTLIER_FACTOR = 10.0
"""A settled run whose peak |e| exceeds this many times the median peak of the runs that set
the range is left out of the range (it is drawn to the edge and annotated)."""
DEGREES_PER_TURN = 360.0
BAND_ALPHA = 0.15
EXIT_MARKER_SIZE = 7
END_MARKER_SIZE = 8
LINE_WIDTH = 1.4
ANNOTATION_FONT_SIZE = 7.5
ANNOTATION_STEP_POINTS = 9.0
"""Vertical offset between annotations that would otherwise sit on one another (points)."""
ANNOTATION_CLOSE = 0.18
"""Annotations at one edge closer than this fraction of the panel's width are staggered."""


class Response(NamedTuple):
    """One response record to draw: e(t) and whether the run stabilised."""

    deviation: np.ndarray
    terminated: bool = False
    settled: bool = True


class Trace(NamedTuple):
    """A controller's line: its median run over seeds, the seeds' range, and how it ends.

    ``centre`` is the median run's own e(t) (cut short when its episode ended early:
    ``ended_early``); ``low`` and ``high`` the range over the seeds at each step while their
    episodes run (NaN where none does); ``falls`` whether the median run falls or diverges
    (:func:`falls_or_diverges`).
    """

    centre: np.ndarray
    low: np.ndarray
    high: np.ndarray
    count: int
    ended_early: bool
    falls: bool = False


class Exit(NamedTuple):
    """Where a drawn trace leaves the y-range: the first sample outside (``index``), the edge it
    crosses (``edge``), the furthest value beyond that edge (``extreme``), and whether the run
    falls or diverges (``falls``; else it is only out of the range chosen for the others)."""

    index: int
    edge: float
    extreme: float
    falls: bool


class Panel(NamedTuple):
    """A panel's decisions: its y-range and one trace per controller."""

    limits: tuple[float, float]
    traces: dict[str, Trace]


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


def final_excursion(response: Response, unwrap: bool, window: int = DEFAULT_FINAL_WINDOW) -> float:
    """Largest :math:`|e|` over the record's last ``window`` samples (angles unwrapped over
    time, so a pendulum that keeps turning ends many degrees away, not within half a turn);
    infinite for a record without a finite sample there."""
    tail = np.abs(_unwrapped(response.deviation, unwrap)[-window:])
    tail = tail[np.isfinite(tail)]
    return float(tail.max()) if tail.size else np.inf


def falls_or_diverges(
    response: Response, hold_band: float, unwrap: bool, window: int = DEFAULT_FINAL_WINDOW
) -> bool:
    """Whether a run falls or diverges, from its record alone (never from a plot's range).

    .. math::

        \\text{falls} = \\text{terminated} \\lor \\big(\\lnot\\,\\text{settled} \\land
            \\max_{t \\ge T - W} |e[t]| > b_{hold}\\big)

    with :math:`W` = ``window`` and :math:`b_{hold}` the system's hold band (the band of its
    "reached and held the operating point" test, e.g. 5 deg, 0.05 m). A run that settles,
    wherever it settles, does not fall; neither does one that keeps moving within the hold band.
    """
    if response.terminated:
        return True
    return not response.settled and final_excursion(response, unwrap, window) > hold_band


def range_records(
    by_key: Mapping[str, Sequence[Response]], hold_band: float, unwrap: bool
) -> list[Response]:
    """The records a panel's y-range covers.

    The first non-empty group of: the runs that settled (not terminated); the runs that do not
    fall or diverge; every run. From that group, outliers are left out: a run whose peak
    :math:`|e|` (angles within half a turn) exceeds :data:`OUTLIER_FACTOR` times the group's
    median peak (kept all when that median is 0).
    """
    records = [r for rs in by_key.values() for r in rs]
    candidates = (
        [r for r in records if r.settled and not r.terminated],
        [r for r in records if not falls_or_diverges(r, hold_band, unwrap)],
        records,
    )
    chosen = next((group for group in candidates if group), [])
    peaks = np.array([_peak(r, unwrap) for r in chosen])
    typical = float(np.median(peaks)) if peaks.size else 0.0
    if typical == 0.0:
        return chosen
    return [r for r, peak in zip(chosen, peaks, strict=True) if peak <= OUTLIER_FACTOR * typical]


def _clipped(response: Response, unwrap: bool) -> np.ndarray:
    """The finite values of a record as the range sees them (angles within half a turn)."""
    values = _unwrapped(response.deviation, unwrap)
    if unwrap:
        half_turn = DEGREES_PER_TURN / 2
        values = np.clip(values, -half_turn, half_turn)
    return values[np.isfinite(values)]


def _peak(response: Response, unwrap: bool) -> float:
    values = _clipped(response, unwrap)
    return float(np.abs(values).max()) if values.size else 0.0


def panel_range(
    by_key: Mapping[str, Sequence[Response]], unwrap: bool, hold_band: float
) -> tuple[float, float]:
    """y-range of a panel: the span of :func:`range_records` and 0, with a margin of
    :data:`Y_MARGIN` of that span on each side."""
    values = [_clipped(r, unwrap) for r in range_records(by_key, hold_band, unwrap)]
    low = min([0.0, *(float(v.min()) for v in values if v.size)])
    high = max([0.0, *(float(v.max()) for v in values if v.size)])
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


def central_trace(
    records: Sequence[Response],
    unwrap: bool,
    limits: tuple[float, float],
    hold_band: float = np.inf,
) -> Trace:
    """The median run (:func:`median_run`) and the range over the seeds, per time step;
    whether the median run falls or diverges is judged with ``hold_band``."""
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
        falls=falls_or_diverges(records[chosen], hold_band, unwrap),
    )


def panel_layout(by_key: Mapping[str, Sequence[Response]], unwrap: bool, hold_band: float) -> Panel:
    """A panel's y-range (:func:`panel_range`) and each controller's trace in it."""
    limits = panel_range(by_key, unwrap, hold_band)
    traces = {
        key: central_trace(records, unwrap, limits, hold_band)
        for key, records in by_key.items()
        if records
    }
    return Panel(limits, traces)


def exit_mark(trace: Trace, limits: tuple[float, float]) -> Exit | None:
    """Where ``trace`` leaves ``limits`` and how far it goes beyond the edge (None: it stays
    inside)."""
    visible = visible_part(trace.centre, limits)
    if visible.exit is None:
        return None
    index, edge = visible.exit
    finite = trace.centre[np.isfinite(trace.centre)]
    extreme = float(finite.max() if edge == limits[1] else finite.min())
    return Exit(index, edge, extreme, trace.falls)


def exit_text(mark: Exit, unit: str, angle: bool) -> str:
    """The annotation at an exit: the trace's extreme beyond the edge ("min -4.15 m"); an angle
    past half a turn is written as such ("min < -180 deg": it went over)."""
    side = "max" if mark.extreme > mark.edge else "min"
    half_turn = DEGREES_PER_TURN / 2
    if angle and abs(mark.extreme) > half_turn:
        bound = "> +" if mark.extreme > 0 else "< -"
        return f"{side} {bound}{half_turn:.0f} {unit}"
    return f"{side} {mark.extreme:+.3g} {unit}"


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
    """Draw one controller's trace (and band, and exit triangle); returns the markers used."""
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
    mark = exit_mark(trace, limits)
    if mark is not None:
        axis.plot(
            time[mark.index],
            mark.edge,
            marker="^" if mark.edge == limits[1] else "v",
            color=colour,
            markerfacecolor=colour if mark.falls else "white",
            markersize=EXIT_MARKER_SIZE,
            clip_on=False,  # whole, not halved by the axes' edge it sits on
        )
        used.add("falls" if mark.falls else "clipped")
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


def _annotate_exits(axis, time, marks: Sequence[tuple[str, Exit]], unit: str, angle: bool):
    """Write each exit's extreme beside its triangle, inside the panel; annotations at one edge
    closer than :data:`ANNOTATION_CLOSE` of the panel's width are stacked inward."""
    width = max(float(time[-1]), 1e-12)
    placed: dict[float, list[float]] = {}
    for key, mark in sorted(marks, key=lambda item: item[1].index):
        x = float(time[mark.index])
        at_edge = placed.setdefault(mark.edge, [])
        near = [other for other in at_edge if abs(other - x) < ANNOTATION_CLOSE * width]
        at_edge.append(x)
        top = mark.extreme > mark.edge
        step = (len(near) + 1) * ANNOTATION_STEP_POINTS
        left = x > width / 2  # write toward the panel's middle
        axis.annotate(
            exit_text(mark, unit, angle),
            (x, mark.edge),
            xytext=(-5 if left else 5, -step if top else step),
            textcoords="offset points",
            ha="right" if left else "left",
            va="center",
            fontsize=ANNOTATION_FONT_SIZE,
            color=controller_colour(key),
        )


def response_caption(
    counts: set[int],
    markers: set[str],
    angles: bool = True,
    controllers: int = 2,
    hold_bands: str = "",
) -> str:
    """The figure's caption: what the line, the band and the markers are (``angles``: some
    panel shows an angle; ``controllers``: how many controllers the figure draws;
    ``hold_bands``: the systems' hold bands, as in "pendulum 5 deg, mountaincar 0.05 m")."""
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
        parts.append(
            "The y-range covers the runs that settle, less any whose peak is over "
            f"{OUTLIER_FACTOR:.0f} times their median peak."
        )
    if "band" in markers:
        parts.append("Shaded: the range over the seeds, where all of them are in the plot.")
    bands = f" ({hold_bands})" if hold_bands else ""
    if "falls" in markers:
        parts.append(
            "Filled triangle: the trace leaves the range there and falls or diverges: its "
            f"episode ended early, or it did not settle and its last {DEFAULT_FINAL_WINDOW} "
            f"samples reach beyond the system's hold band{bands}."
        )
    if "clipped" in markers:
        parts.append(
            "Open triangle: the trace leaves the range there but does not fall (it settles, or "
            "stays within the hold band, out of the range)."
        )
    if markers & {"falls", "clipped"}:
        parts.append("Beside each triangle: how far the trace goes beyond the edge.")
    if "terminated" in markers:
        parts.append("A cross: the episode ended early (the cart left its track).")
    return " ".join(parts)


def _unit(system: Any) -> str:
    """The main coordinate's unit, from its label ("x [m]" -> "m")."""
    label = str(system.main_label)
    if "[" in label and label.endswith("]"):
        return label[label.rindex("[") + 1 : -1]
    return "deg" if system.main_in_degrees else ""


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
            limits, traces = panel_layout(by_key, unwrap, system.hold_band)
            length = max((len(r.deviation) for rs in by_key.values() for r in rs), default=1)
            time = np.arange(length) * system.dt
            exits = []
            for key, trace in traces.items():
                counts.add(trace.count)
                markers |= _draw_trace(axis, time, trace, limits, key, bands)
                mark = exit_mark(trace, limits)
                if mark is not None:
                    exits.append((key, mark))
                handles.setdefault(
                    labels.get(key, key),
                    plt.Line2D(
                        [], [], color=controller_colour(key), linestyle=controller_style(key)
                    ),
                )
            _annotate_exits(axis, time, exits, _unit(system), unwrap)
            axis.set_ylim(*limits)
            axis.set_xlim(0.0, time[-1])
            axis.axhline(0.0, color="#bbbbbb", linewidth=0.8, zorder=0)
            axis.set_title(f"{system_name}: {test} response")
            axis.set_xlabel("time [s]")
            axis.set_ylabel(f"deviation of {system.main_label}")
    _response_legend(figure, responses, handles, labels, markers, counts)
    return figure


def _response_legend(
    figure: Any,
    responses: Mapping[str, Mapping[str, Mapping[str, Sequence[Any]]]],
    handles: dict[str, Any],
    labels: Mapping[str, str],
    markers: set[str],
    counts: set[int],
) -> None:
    """The legend of :func:`draw_responses` below its panels: the controllers in the order of
    ``labels``, the markers drawn, and the caption."""
    plt = pyplot()
    systems = list(responses)
    order = list(labels.values())
    handles = dict(
        sorted(
            handles.items(),
            key=lambda item: order.index(item[0]) if item[0] in order else len(order),
        )
    )
    if "falls" in markers:
        handles["falls or diverges (leaves the range)"] = plt.Line2D(
            [], [], color="k", marker="^", linestyle="none"
        )
    if "clipped" in markers:
        handles["out of the range, does not fall"] = plt.Line2D(
            [], [], color="k", marker="^", markerfacecolor="white", linestyle="none"
        )
    if "terminated" in markers:
        handles["episode ended early"] = plt.Line2D([], [], color="k", marker="X", linestyle="none")
    made = {name: make_system(name) for name in systems}
    angles = any(system.main_in_degrees for system in made.values())
    hold_bands = ", ".join(f"{name} {s.hold_band:g} {_unit(s)}" for name, s in made.items())
    keys = {key for by_test in responses.values() for t in by_test.values() for key in t}
    caption = response_caption(counts, markers, angles, len(keys), hold_bands)
    legend_below(figure, handles, caption)


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
