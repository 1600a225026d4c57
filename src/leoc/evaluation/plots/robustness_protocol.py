"""The robustness protocol's scores (:mod:`leoc.evaluation.robustness_protocol`): per category
and controller the share of episodes held, as grouped bars, with the robustness score (the
categories' mean) as the last group; one panel per start selection (every start, the
operating region, the swing-up start).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from leoc.evaluation.plots.common import (
    axes_handles,
    controller_colour,
    legend_below,
    new_figure,
    save_figure,
)

PANELS = {
    None: "every start (the protocol's score)",
    "operating_region": "from the operating region",
    "swing_up": "from the swing-up start",
}
"""The panels, top to bottom: the start kind each scores (None: all) and its title."""
GROUP_WIDTH = 0.8
"""Width of one category's group of bars, in category spacings."""
HATCHES = ("", "//", "..", "xx", "\\\\", "++", "oo", "--")
"""Bar fill patterns, one per controller in turn (told apart where colours coincide)."""
PANEL_HEIGHT = 2.7
PANEL_WIDTH_PER_GROUP = 1.15
SCORE_LIMITS = (0.0, 1.25)  # room above 1.0 for an upright score label
ROBUSTNESS = "robustness"


def protocol_caption(results: Mapping[str, Any], runs: Mapping[str, int] | None = None) -> str:
    """What each bar is. ``runs`` maps a label to the number of runs its result pools (its
    training seeds, by :func:`leoc.experiments.report.robustness_protocol.pooled`; 1 where a
    label is missing): a pooled result holds that many times one run's episodes per level."""
    runs = dict(runs or {})
    first_label, first = next(iter(results.items()))
    per_run = first.episodes // max(1, runs.get(first_label, 1))
    pooling = max(runs.values(), default=1) > 1
    return (
        f"Robustness protocol on {first.system} (protocol seed {first.seed}): each bar is the "
        f"share of the episodes held (leoc's hold test) over the category's levels, up to "
        f"{first.level_count} from none to the level at which the LQR fails, with "
        f"{per_run} episode{'s' if per_run != 1 else ''} per level and start kind"
        + (
            " in each run; a controller trained on several seeds pools the episodes of its "
            "runs (one per seed)"
            if pooling
            else ""
        )
        + f"; '{ROBUSTNESS}' is the mean of the categories."
    )


def _draw_panel(axis: Any, results: Mapping[str, Any], keys: Mapping[str, str], kind) -> None:
    """The grouped bars of one start selection ``kind`` on ``axis``."""
    names = [category.name for category in next(iter(results.values())).categories]
    groups = [*names, ROBUSTNESS]
    width = GROUP_WIDTH / max(1, len(results))
    for index, (label, result) in enumerate(results.items()):
        scores = result.scores(kind)
        values = [scores.get(name, np.nan) for name in names] + [result.score(kind)]
        offsets = np.arange(len(groups)) - GROUP_WIDTH / 2 + (index + 0.5) * width
        axis.bar(
            offsets,
            values,
            width,
            color=controller_colour(keys.get(label, label)),
            hatch=HATCHES[index % len(HATCHES)],
            edgecolor="white",
            linewidth=0.5,
            label=label,
        )
        axis.annotate(
            f"{values[-1]:.2f}",
            (offsets[-1], values[-1]),
            textcoords="offset points",
            xytext=(0, 2),
            ha="center",
            va="bottom",
            rotation=90,  # upright: the scores of neighbouring bars never overlap
            fontsize="x-small",
        )
    axis.axvline(len(names) - 0.5, color="#999999", linewidth=0.8)
    axis.set_xticks(range(len(groups)), [name.replace("_", "\n") for name in groups])
    axis.set_ylim(*SCORE_LIMITS)
    axis.set_ylabel("share held")
    axis.set_title(PANELS[kind])
    axis.grid(axis="y", alpha=0.3)


def draw_protocol_scores(
    results: Mapping[str, Any],
    keys: Mapping[str, str] | None = None,
    runs: Mapping[str, int] | None = None,
):
    """The figure of :func:`plot_protocol_scores` (not saved)."""
    keys = dict(keys or {})
    first = next(iter(results.values()))
    kinds = [kind for kind in PANELS if kind is None or kind in first.starts]
    groups = len(first.categories) + 1
    figure, axes = new_figure(len(kinds), 1, (PANEL_WIDTH_PER_GROUP * groups, PANEL_HEIGHT))
    for row, kind in enumerate(kinds):
        _draw_panel(axes[row][0], results, keys, kind)
    legend_below(figure, axes_handles(axes), protocol_caption(results, runs))
    return figure


def plot_protocol_scores(
    results: Mapping[str, Any],
    path: str | Path,
    keys: Mapping[str, str] | None = None,
    runs: Mapping[str, int] | None = None,
) -> Path:
    """Write the scores of ``results`` to ``path`` as a PNG: bars per category and controller,
    the controllers side by side in the order given, coloured by ``keys``.

    ``results`` maps a label to its
    :class:`~leoc.evaluation.robustness_protocol.ProtocolResult` (one system); ``keys`` maps a
    label to a controller name such as ``linear`` or ``ddpg_hybrid`` (default the label);
    ``runs`` maps a label to the number of runs its result pools (default 1, see
    :func:`protocol_caption`).
    """
    if not results:
        raise ValueError("results: expected at least one controller's result, found none")
    return save_figure(draw_protocol_scores(results, keys, runs), path)
