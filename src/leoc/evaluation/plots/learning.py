"""Learning curves (the paper's figure 6): return against interaction time, baseline and hybrid,
one row per framework (DDPG and PILCO as in the paper; SAC too when the report has its curves)
and one column per system."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from leoc.evaluation.plots.common import (
    axes_handles,
    controller_colour,
    controller_style,
    legend_below,
    new_figure,
    save_figure,
)
from leoc.names import FRAMEWORKS, controller_framework

PAPER_FRAMEWORKS = ("ddpg", "pilco")  # rows drawn even without curves (the paper's figure 6)
KINDS = ("baseline", "hybrid")
BAND_ALPHA = 0.2
MARKER_BELOW_POINTS = 20
"""Curves with fewer grid points than this get a dot per evaluation."""
MIN_SEEDS_FOR_BAND = 2
"""Fewest seeds with a spread to shade; one seed is drawn as its line alone."""


def _centre_and_band(curve: Mapping[str, Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray, str]:
    """IQM with its 95% bootstrap band (>= 3 seeds), else the mean and +/- one std."""
    if "iqm" in curve:
        centre = np.array(curve["iqm"])
        return centre, np.array(curve["ci_low"]), np.array(curve["ci_high"]), "iqm"
    centre, std = np.array(curve["mean"]), np.array(curve["std"])
    return centre, centre - std, centre + std, "mean"


def band_kind(curve: Mapping[str, Any]) -> str:
    """What a curve's line is and whether it has a band: ``"iqm"`` (IQM and its bootstrap
    interval), ``"mean"`` (mean +/- one std, two seeds) or ``"single"`` (one seed: its own
    curve, no band, as there is no spread to show)."""
    if int(curve["n_seeds"]) < MIN_SEEDS_FOR_BAND:
        return "single"
    return _centre_and_band(curve)[3]


def learning_caption(seeds_by_kind: Mapping[str, set[int]]) -> str:
    """What the lines and bands are, from the :func:`band_kind` of each curve drawn mapped to
    the seed counts of those curves. A band is described only when one is drawn."""

    def seeds(kind: str) -> str:
        return "/".join(str(n) for n in sorted(seeds_by_kind[kind]))

    parts = [
        "Return of the evaluation episodes (sum of rewards per 200-step episode, higher is "
        "better) against the interaction time the learner had used (simulated seconds)."
    ]
    if "iqm" in seeds_by_kind:
        parts.append(
            f"Line: interquartile mean over the {seeds('iqm')} seeds; shaded: its 95% "
            "stratified-bootstrap confidence interval."
        )
    if "mean" in seeds_by_kind:
        parts.append(
            f"Line: mean over the {seeds('mean')} seeds; shaded: +/- one standard deviation "
            "(too few seeds for an interval)."
        )
    if "single" in seeds_by_kind:
        if len(seeds_by_kind) > 1:
            parts.append("A controller with one seed: its run's evaluation return, no band.")
        else:
            parts.append("Line: the evaluation return of the one seed (no band).")
    return " ".join(parts)


def draw_learning_curves(
    curves: Mapping[str, Mapping[str, Any]], labels: Mapping[str, str] | None = None
):
    """The figure of :func:`plot_learning_curves` (not saved)."""
    labels = dict(labels or {})
    systems = list(curves)
    drawn = {
        controller_framework(key) for by_controller in curves.values() for key in by_controller
    }
    frameworks = [name for name in FRAMEWORKS if name in PAPER_FRAMEWORKS or name in drawn]
    figure, axes = new_figure(len(frameworks), max(1, len(systems)), (4.2, 3.0))
    seeds_by_kind: dict[str, set[int]] = {}
    for column, system in enumerate(systems):
        for row, framework in enumerate(frameworks):
            axis = axes[row][column]
            for kind in KINDS:
                key = f"{framework}_{kind}"
                curve = curves[system].get(key)
                if curve is None:
                    continue
                seconds = np.array(curve["seconds"])
                centre, low, high, _ = _centre_and_band(curve)
                kind = band_kind(curve)
                seeds_by_kind.setdefault(kind, set()).add(int(curve["n_seeds"]))
                colour = controller_colour(key)
                axis.plot(
                    seconds,
                    centre,
                    color=colour,
                    linestyle=controller_style(key),
                    marker="." if len(seconds) < MARKER_BELOW_POINTS else None,
                    label=labels.get(key, key),
                )
                if kind != "single":
                    axis.fill_between(seconds, low, high, color=colour, alpha=BAND_ALPHA, lw=0)
            axis.set_title(f"{system}: {framework.upper()}")
            axis.set_xlabel("interaction time [s]")
            axis.set_ylabel("evaluation return")
    legend_below(figure, axes_handles(axes), learning_caption(seeds_by_kind))
    return figure


def plot_learning_curves(
    curves: Mapping[str, Mapping[str, Any]],
    path: str | Path,
    labels: Mapping[str, str] | None = None,
) -> Path:
    """Figure 6: return vs interaction time, baseline vs hybrid, rows = framework.

    ``curves``: system -> controller -> the report's curve summary (``seconds``, ``mean``,
    ``std``, ``n_seeds`` and, with three seeds or more, ``iqm``, ``ci_low``, ``ci_high``).
    """
    return save_figure(draw_learning_curves(curves, labels), path)
