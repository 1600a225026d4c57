"""The relevance ablation's trade-off figure: how far a learned hybrid's impulse response is
from its LQR's, against how soon it learned the swing-up; one point per run, one panel per
system and learner (:mod:`leoc.experiments.relevance_report`)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from leoc.evaluation.plots.common import axes_handles, legend_below, new_figure, save_figure

#: Colours of the relevance settings (the rest cycle through matplotlib's tab10).
PALETTE = (
    "#222222",
    "#d62728",
    "#1f77b4",
    "#ff7f0e",
    "#2ca02c",
    "#9467bd",
    "#8c564b",
    "#e377c2",
    "#17becf",
    "#bcbd22",
)
MARKERS = ("o", "s", "^", "D", "v", "P", "X", "<", ">", "*")
#: Where runs that never held are drawn, as a fraction above the largest first-hold time.
NEVER_MARGIN = 1.15
#: Smallest distance drawn on the log axis [%] (a run equal to its LQR to round-off).
DISTANCE_FLOOR = 1e-5


def _panels(points: Sequence[Mapping[str, Any]]) -> list[tuple[str, str]]:
    from leoc.names import controller_framework

    keys = {(p["system"], controller_framework(p["controller"])) for p in points}
    return sorted(keys)


def _never_level(points: Sequence[Mapping[str, Any]]) -> float:
    held = [p["first_hold_s"] for p in points if p["first_hold_s"] is not None]
    return NEVER_MARGIN * (max(held) if held else 100.0)


def _draw(axis: Any, points: Sequence[Mapping[str, Any]], style: dict, labels: Mapping) -> None:
    never = _never_level(points)
    for setting, (colour, marker) in style.items():
        mine = [p for p in points if p["setting"] == setting]
        if not mine:
            continue
        x = [
            max(p["distance_pct"], DISTANCE_FLOOR) if math.isfinite(p["distance_pct"]) else 1e4
            for p in mine
        ]
        y = [never if p["first_hold_s"] is None else p["first_hold_s"] for p in mine]
        axis.scatter(
            x,
            y,
            color=colour,
            marker=marker,
            s=28,
            alpha=0.8,
            label=labels.get(setting, setting),
        )
    axis.axhline(never, color="#999999", lw=0.8, ls=":")
    axis.text(axis.get_xlim()[0], never, " never held", va="bottom", fontsize="x-small")


def plot_relevance_tradeoff(
    points: Sequence[Mapping[str, Any]],
    path: str | Path,
    labels: Mapping[str, str],
    tolerance_pct: float,
) -> Path:
    """One point per run: ``distance_pct`` (log x) against ``first_hold_s`` (y; None drawn on
    a dotted "never held" line above the others), coloured by ``setting``, one panel per
    system (columns) and learner (rows; a learner without runs on a system leaves its panel
    empty); a vertical line at ``tolerance_pct``."""
    panels = _panels(points)
    settings = list(dict.fromkeys(p["setting"] for p in points))
    style = {
        name: (PALETTE[i % len(PALETTE)], MARKERS[i % len(MARKERS)])
        for i, name in enumerate(settings)
    }
    systems = list(dict.fromkeys(system for system, _ in panels)) or [""]
    learners = sorted({learner for _, learner in panels}) or [""]
    figure, axes = new_figure(len(learners), len(systems), panel=(4.6, 3.4))
    for axis in np.ravel(axes):
        axis.set_visible(False)  # shown again below where a system has runs of that learner
    for system, learner in panels:
        axis = axes[learners.index(learner), systems.index(system)]
        axis.set_visible(True)
        mine = [p for p in points if p["system"] == system and p["controller"].startswith(learner)]
        axis.set_xscale("log")
        _draw(axis, mine, style, labels)
        axis.axvline(tolerance_pct, color="#d62728", lw=1.0, ls="--")
        axis.set_title(f"{system}, {learner.upper()} hybrid", fontsize="medium")
        axis.set_xlabel("impulse response's distance from the LQR's [% of its peak]")
        axis.set_ylabel("interaction time to first hold [s]")
        axis.grid(True, which="both", alpha=0.25)
    caption = (
        "One point per run (seed). Left of the dashed red line the hybrid keeps its LQR's "
        f"impulse response (within {tolerance_pct:g} % of its peak); lower is learning the "
        "swing-up sooner. Runs whose held-out swing-ups never all held sit on the dotted line. "
        "Runs with r == 1 all along the response (the ROA hybrids) equal their LQR by "
        "construction and are left out."
    )
    legend_below(figure, axes_handles(axes), caption)
    return save_figure(figure, path)
