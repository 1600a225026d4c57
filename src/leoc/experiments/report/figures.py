"""The report's figures: learning curves over seeds, and every figure drawn from the tables
(paper figures 4, 6, 7 and 8, the basins, the animations), each a section of its own."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from leoc.evaluation.plots.basins import plot_basins_summary
from leoc.evaluation.plots.learning import plot_learning_curves
from leoc.evaluation.plots.relevance import plot_relevance
from leoc.evaluation.plots.responses import plot_responses
from leoc.evaluation.plots.robustness import plot_robustness
from leoc.evaluation.robustness import SCALED_PARAMETERS
from leoc.evaluation.rollout import RESPONSE_TESTS
from leoc.experiments.animations import write_report_animations
from leoc.experiments.layout import Evaluations
from leoc.experiments.profiles import CONTROLLER_LABELS, CONTROLLERS
from leoc.experiments.report.base import Report, Section, Study
from leoc.experiments.report.robustness_protocol import write_protocol_figures
from leoc.experiments.stats import MIN_RUNS_FOR_INTERVAL, curve_bands
from leoc.systems import make_system

CURVE_GRID_POINTS = 50


def curve_summary(runs: list[dict[str, Any]]) -> dict[str, Any] | None:
    """Learning curves over seeds on a common grid (each seed's curve linearly interpolated;
    the grid spans the seconds all seeds reached): mean and std, and with at least three seeds
    the point-wise IQM with its 95 % bootstrap band (:func:`leoc.experiments.stats.curve_bands`).
    """
    curves = [run["curve"] for run in runs if run.get("curve") and run["curve"]["seconds"]]
    if not curves:
        return None
    end = min(curve["seconds"][-1] for curve in curves)
    start = max(curve["seconds"][0] for curve in curves)
    grid = np.linspace(start, end, CURVE_GRID_POINTS) if end > start else np.array([end])
    values = np.array([np.interp(grid, c["seconds"], c["returns"]) for c in curves])
    summary: dict[str, Any] = {
        "seconds": grid.tolist(),
        "mean": values.mean(0).tolist(),
        "std": values.std(0).tolist(),
        "n_seeds": len(curves),
    }
    if len(curves) >= MIN_RUNS_FOR_INTERVAL:
        bands = curve_bands(values)
        summary.update(
            iqm=np.asarray(bands.iqm).tolist(),
            ci_low=np.asarray(bands.ci_low).tolist(),
            ci_high=np.asarray(bands.ci_high).tolist(),
        )
    return summary


def relevance_traces(evaluations: Evaluations) -> dict[tuple[str, str], dict[str, Any]]:
    """The first seed's swing-up relevance trace of every hybrid, by (system, controller)."""
    return {
        (system, controller): runs[0]["relevance"]
        for system, by_controller in evaluations.items()
        for controller, runs in by_controller.items()
        if runs and runs[0].get("relevance")
    }


def write_relevance_figure(evaluations: Evaluations, path: Path) -> Path | None:
    """Figure 4 (``relevance.png``), or None when no run has a relevance trace."""
    traces = relevance_traces(evaluations)
    if not traces:
        return None
    names = list(dict.fromkeys(system for system, _ in traces))
    systems = {name: make_system(name) for name in names}
    return plot_relevance(
        traces,
        path,
        systems,
        [c for c in CONTROLLERS if any(c == k for _, k in traces)],
        {name: system.episode_steps * system.dt for name, system in systems.items()},
        CONTROLLER_LABELS,
    )


def _response_records(runs: list[dict[str, Any]], test: str) -> list[dict[str, Any]]:
    return [
        {
            "deviation": run["responses"][test]["deviation"],
            "terminated": run["responses"][test]["metrics"].get("terminated", False),
            "settled": run["responses"][test]["metrics"]["settled"],
        }
        for run in runs
    ]


def _write_responses_figure(evaluations: Evaluations, path: Path) -> None:
    """Figure 7: every controller's impulse and step responses, seed by seed."""
    records = {
        system: {
            test: {c: _response_records(runs, test) for c, runs in by_c.items()}
            for test in RESPONSE_TESTS
        }
        for system, by_c in evaluations.items()
    }
    plot_responses(records, path, CONTROLLER_LABELS)


def write_figures(study: Study, tables: dict[str, Any]) -> list[tuple[str, str]]:
    """Draw every figure the tables allow into the study's folder: (title, file) of each, in
    the report's order (the robustness protocol's figures are drawn too, and shown in their
    own section, not listed)."""
    out, evaluations = study.out, study.evaluations
    figures = []
    if evaluations:
        _write_responses_figure(evaluations, out / "responses.png")
        figures.append(("Impulse and step responses (paper figure 7)", "responses.png"))
    if any(tables["curves"].values()):
        plot_learning_curves(tables["curves"], out / "learning_curves.png", CONTROLLER_LABELS)
        figures.append(("Learning curves (paper figure 6)", "learning_curves.png"))
    if tables["robustness"]:
        plot_robustness(
            tables["robustness"],
            out / "robustness.png",
            CONTROLLERS,
            SCALED_PARAMETERS,
            CONTROLLER_LABELS,
        )
        figures.append(("Robustness (paper figure 8)", "robustness.png"))
    if tables["roa"]:
        plot_basins_summary(tables["roa"], out / "basins.png", CONTROLLER_LABELS)
        figures.append(("Empirical basins and the certified region of attraction", "basins.png"))
    if write_relevance_figure(evaluations, out / "relevance.png"):
        figures.append(("Relevance along a swing-up (paper figure 4)", "relevance.png"))
    # drawn here, once the numbers are written; shown in the robustness protocol's section
    write_protocol_figures(study)
    for system, animation in write_report_animations(out, evaluations).items():
        title = f"{system}: a hybrid's swing-up and impulse response, r(x) shown"
        figures.append((title, animation.relative_to(out).as_posix()))
    return figures


def compute(study: Study) -> dict[str, Any]:
    """The ``curves`` table: :func:`curve_summary` per system and controller (those with one)."""
    return {
        "curves": {
            system: {c: curve_summary(runs) for c, runs in by_c.items() if curve_summary(runs)}
            for system, by_c in study.evaluations.items()
        }
    }


def render(report: Report) -> list[str]:
    """One ``##`` section per figure written, then where the numbers are."""
    lines = []
    for title, filename in report.figures:
        lines += ["", f"## {title}", "", f"![{title}]({filename})"]
    return lines + [
        "",
        "All numbers: results.json, responses.csv, robustness.csv, swing_up.csv, "
        "learning_curves.csv. Regenerate figures and this report: `leoc plot <folder>`.",
        "",
    ]


SECTION = Section(render, compute)
