"""Figures: response plots with consistent colours per controller.

matplotlib is imported inside the functions (Agg backend), so importing this module is cheap and
works without a display.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from leoc.io import save_figure_atomic
from leoc.systems import make_system

CONTROLLER_COLOURS = {
    "linear": "#222222",
    "ddpg_baseline": "#1f77b4",
    "ddpg_hybrid": "#17becf",
    "td3_baseline": "#9467bd",
    "td3_hybrid": "#e377c2",
    "pilco_baseline": "#d62728",
    "pilco_hybrid": "#ff7f0e",
}
CONTROLLER_STYLES = {"linear": "-", "ddpg_hybrid": "--", "pilco_hybrid": ":", "td3_hybrid": "--"}
FIGURE_DPI = 120
PANEL_SIZE = (4.2, 3.0)


def controller_colour(label: str) -> str:
    return CONTROLLER_COLOURS.get(label, "#7f7f7f")


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(figure, path: str | Path) -> Path:
    """Save ``figure`` to ``path`` atomically and close it."""
    return save_figure_atomic(figure, path, dpi=FIGURE_DPI)


def plot_responses(
    responses: Mapping[str, Mapping[str, Mapping[str, Sequence[np.ndarray]]]],
    path: str | Path,
) -> Path:
    """Grid of responses: rows = tests (impulse, step), columns = systems.

    Parameters
    ----------
    responses : mapping system -> test -> controller label -> list of deviations e(t) (seeds)
        Every seed is drawn as a line in the controller's colour.
    path : output PNG path
    """
    plt = _pyplot()
    systems = list(responses)
    tests = sorted({test for by_test in responses.values() for test in by_test})
    figure, axes = plt.subplots(
        len(tests),
        len(systems),
        figsize=(PANEL_SIZE[0] * len(systems), PANEL_SIZE[1] * len(tests)),
        squeeze=False,
    )
    for column, system_name in enumerate(systems):
        system = make_system(system_name)
        for row, test in enumerate(tests):
            axis = axes[row][column]
            for label, deviations in responses[system_name].get(test, {}).items():
                for index, deviation in enumerate(deviations):
                    time = np.arange(len(deviation)) * system.dt
                    axis.plot(
                        time,
                        deviation,
                        color=controller_colour(label),
                        linestyle=CONTROLLER_STYLES.get(label, "-"),
                        linewidth=1.2,
                        label=label if index == 0 else None,
                    )
            axis.axhline(0.0, color="#bbbbbb", linewidth=0.8)
            axis.set_title(f"{system_name}: {test} response")
            axis.set_xlabel("time [s]")
            axis.set_ylabel(f"deviation of {system.main_label}")
            axis.legend(fontsize="small")
    figure.tight_layout()
    return save_figure(figure, path)
