"""The report's robustness protocol: per category of perturbation the share of episodes each
controller holds (``evaluation.json``'s ``robustness_protocol``,
:func:`leoc.experiments.evaluators.evaluate_robustness_protocol`), over seeds, and one figure
per system (``robustness_protocol_SYSTEM.png``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from leoc.evaluation.robustness_protocol import (
    CATEGORY_NAMES,
    CategoryResult,
    LevelResult,
    ProtocolResult,
)
from leoc.experiments.layout import Evaluations
from leoc.experiments.markdown import markdown_table
from leoc.experiments.report.base import FMT, Report, Rows, Section, Study, label, ordered

KEY = "robustness_protocol"
"""The runs' entry the section reads (``evaluation.json``)."""
SCORE = "robustness"
"""The column of the categories' mean (the robustness score)."""
NOT_MEASURED = (
    "Not measured for these runs: they were written before `leoc reproduce` ran the "
    "robustness protocol (`leoc robustness RUN_DIR` scores one run)."
)
"""The section's text for a study whose runs have no ``robustness_protocol`` entry."""
NO_MAXIMA = (
    "Not measured: no system of these runs has measured maximum levels "
    "(`leoc robustness SYSTEM --calibrate` measures them; "
    "`leoc.evaluation.robustness_protocol.DEFAULT_MAX_LEVELS` holds them)."
)
"""The section's text for a study whose runs have the entry, None for every one of them."""


def figure_name(system: str) -> str:
    """The file of ``system``'s figure in the study's folder."""
    return f"robustness_protocol_{system}.png"


def _spread(values: list[float]) -> dict[str, float]:
    return {
        "median": float(np.median(values)),
        "min": float(np.min(values)),
        "max": float(np.max(values)),
    }


def _row(system: str, controller: str, results: list[ProtocolResult]) -> dict[str, Any]:
    """One controller's scores over its seeds (each seed's protocol: ``results``)."""
    scores = [result.scores() for result in results]
    names = [name for name in CATEGORY_NAMES if name in scores[0]]
    first = results[0]
    return {
        "system": system,
        "controller": controller,
        "n_runs": len(results),
        "levels": first.level_count,
        "episodes": first.episodes,
        "seed": first.seed,
        "max_levels": first.max_levels,
        "scores": {name: _spread([score[name] for score in scores]) for name in names},
        SCORE: _spread([result.score() for result in results]),
        "per_seed": [
            {**score, SCORE: result.score()} for score, result in zip(scores, results, strict=True)
        ],
    }


def protocol_results(evaluations: Evaluations) -> dict[str, dict[str, list[ProtocolResult]]]:
    """Per system and controller (report order), the protocol of each run that has one."""
    found: dict[str, dict[str, list[ProtocolResult]]] = {}
    for system, by_controller in evaluations.items():
        for controller in ordered(by_controller):
            records = [run[KEY] for run in by_controller[controller] if run.get(KEY)]
            if records:
                results = [ProtocolResult.from_dict(record) for record in records]
                found.setdefault(system, {})[controller] = results
    return found


def protocol_summary(evaluations: Evaluations) -> Rows:
    """Rows: system, controller, the protocol's levels, episodes and seed, and per category
    and for the robustness score (their mean) the median, least and largest over seeds, with
    every seed's scores."""
    return [
        _row(system, controller, results)
        for system, by_controller in protocol_results(evaluations).items()
        for controller, results in by_controller.items()
    ]


def pooled(results: list[ProtocolResult]) -> ProtocolResult:
    """One result whose every level holds the episodes of all ``results`` (seeds of one
    controller run with one protocol): its shares are the seeds' mean shares."""
    first = results[0]
    categories = []
    for index, category in enumerate(first.categories):
        levels = []
        for position, level in enumerate(category.levels):
            runs = [result.categories[index].levels[position] for result in results]
            held = {kind: [h for run in runs for h in run.held[kind]] for kind in level.held}
            levels.append(LevelResult(level.level, level.constant, held, level.perturbations))
        categories.append(CategoryResult(category.name, category.max_level, levels))
    return first._replace(episodes=first.episodes * len(results), categories=categories)


def write_protocol_figures(study: Study) -> list[Path]:
    """``robustness_protocol_SYSTEM.png`` per system with protocol results: every controller's
    scores side by side (its seeds pooled), drawn by
    :func:`leoc.evaluation.plots.robustness_protocol.plot_protocol_scores`."""
    from leoc.evaluation.plots.robustness_protocol import plot_protocol_scores

    written = []
    for system, by_controller in protocol_results(study.evaluations).items():
        results = {label(c): pooled(runs) for c, runs in by_controller.items()}
        keys = {label(c): c for c in by_controller}
        written.append(plot_protocol_scores(results, study.out / figure_name(system), keys))
    return written


def _cell(spread: dict[str, float]) -> str:
    """``median [least, largest]`` (the median alone when they agree)."""
    if spread["min"] == spread["max"]:
        return f"{spread['median']:.2f}"
    return f"{spread['median']:.2f} [{spread['min']:.2f}, {spread['max']:.2f}]"


def protocol_table(rows: Rows) -> list[str]:
    """Markdown rows of one system's table: per controller, every category's score and the
    robustness score."""
    names = [name for name in CATEGORY_NAMES if name in rows[0]["scores"]]
    headers = ["controller", "seeds", *(name.replace("_", " ") for name in names), SCORE]
    table = [
        [
            label(row["controller"]),
            str(row["n_runs"]),
            *(_cell(row["scores"][name]) for name in names),
            _cell(row[SCORE]),
        ]
        for row in rows
    ]
    return markdown_table(headers, table)


def _maxima(row: dict[str, Any]) -> str:
    """The maximum level of each category (the end of its sweep)."""
    levels = row["max_levels"]
    return ", ".join(
        f"{name.replace('_', ' ')} {FMT.format(levels[name])}"
        for name in CATEGORY_NAMES
        if name in levels
    )


def _system_lines(system: str, rows: Rows) -> list[str]:
    constants = ", ".join(rows[0]["max_levels"]["constants"])
    return [
        "",
        f"### {system}",
        "",
        f"Sweeps up to: {_maxima(rows[0])} (parameter errors of {constants}, one at a time).",
        "",
        *protocol_table(rows),
        "",
        f"![Robustness protocol: {system}]({figure_name(system)})",
    ]


METHOD = (
    "Each controller on its nominal plant perturbed one category at a time "
    "(`leoc.evaluation.robustness_protocol`, `leoc robustness`; after RealAIGym's "
    "leaderboard): velocity observation noise, action delay, actuator gain, torque noise, "
    "viscous and Coulomb friction, parameter errors (one constant at a time) and pushes, each "
    "swept from none to the level at which leoc's LQR holds none of ten operating-region "
    "episodes. At every level, episodes from the operating region and from the swing-up start "
    "pass or fail leoc's hold test. A category's score is the share of its episodes held, the "
    "robustness score their mean. One protocol seed for every controller: the same starts, "
    "noise and pushes (a paired comparison). Cells: median [least, largest] over seeds; the "
    "figures pool the seeds."
)
"""The section's opening paragraph."""


def compute(study: Study) -> dict[str, Any]:
    """The ``robustness_protocol`` table (:func:`protocol_summary`)."""
    return {"robustness_protocol": protocol_summary(study.evaluations)}


def render(report: Report) -> list[str]:
    """``## Robustness protocol``: the method and its budget, then per system its maximum
    levels, the table and the figure; or that the runs did not measure it."""
    rows = report.tables["robustness_protocol"]
    lines = ["", "## Robustness protocol", ""]
    if not rows:
        runs = [
            run for by_c in report.study.evaluations.values() for r in by_c.values() for run in r
        ]
        return [*lines, NO_MAXIMA if any(KEY in run for run in runs) else NOT_MEASURED]
    first = rows[0]
    lines += [
        METHOD,
        "",
        f"Budget: {first['levels']} levels per category (parameter errors: per constant), "
        f"{first['episodes']} episode{'s' if first['episodes'] != 1 else ''} per level from "
        f"each start, protocol seed {first['seed']}.",
    ]
    for system in dict.fromkeys(row["system"] for row in rows):
        lines += _system_lines(system, [row for row in rows if row["system"] == system])
    return lines


SECTION = Section(render, compute)
