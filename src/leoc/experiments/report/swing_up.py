"""The report's swing-up: each controller from the seeded swing-up starts, and the check that
every learned controller swings up and holds."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from leoc.experiments.layout import SWING_UP_EPISODES, Evaluations
from leoc.experiments.markdown import markdown_table
from leoc.experiments.profiles import LINEAR_CONTROLLERS
from leoc.experiments.report.base import (
    FMT,
    Check,
    Report,
    Rows,
    Section,
    Study,
    flag_block,
    label,
    ordered,
    pm,
)
from leoc.experiments.stats import percent, success_interval
from leoc.experiments.summary import Failure


def swing_up_summary(evaluations: Evaluations) -> Rows:
    """Rows: system, controller, mean return and fraction of swing-up episodes that held, runs
    whose every episode held, mean hold step."""
    rows = []
    for system, by_controller in evaluations.items():
        for controller in ordered(by_controller):
            runs = by_controller[controller]
            returns = np.concatenate([run["swing_up"]["returns"] for run in runs])
            holds = [h for run in runs for h in run["swing_up"]["hold_steps"]]
            held = [h for h in holds if h is not None]
            all_held = sum(run["swing_up"]["held_fraction"] >= 1.0 for run in runs)
            interval = success_interval(all_held, len(runs))
            rows.append(
                {
                    "system": system,
                    "controller": controller,
                    "return_mean": float(returns.mean()),
                    "return_std": float(returns.std()),
                    "fraction_held": len(held) / len(holds) if holds else 0.0,
                    "runs_all_held": all_held,
                    "runs_all_held_ci_low": interval[0],
                    "runs_all_held_ci_high": interval[1],
                    "n_runs": len(runs),
                    "mean_hold_step": float(np.mean(held)) if held else math.nan,
                }
            )
    return rows


def _swing_up_failures(rows: Rows) -> tuple[int, list[Failure]]:
    """The learned controllers, and those that do not swing up and hold in every episode (size:
    the share of episodes that did not hold), in the rows' order."""
    learned = [row for row in rows if row["controller"] not in LINEAR_CONTROLLERS]
    return len(learned), [
        Failure(
            f"{row['system']} {label(row['controller'])}",
            1.0 - row["fraction_held"],
            f"{percent(row['fraction_held'])} held",
            "",
            f"**{row['system']} {label(row['controller'])}** does not swing up and hold: "
            f"{percent(row['fraction_held'])} of its swing-up episodes held the operating point.",
        )
        for row in learned
        if row["fraction_held"] < 1.0
    ]


#: The check: every learned controller swings up and holds in every episode.
SWING_UP_CHECK = Check(
    "swing_up",
    _swing_up_failures,
    cases="learned controllers",
    threshold="every swing-up episode holds",
    worked="swing up and hold in every episode",
)


def _swing_up_cells(row: dict[str, Any]) -> list[str]:
    hold = "-" if math.isnan(row["mean_hold_step"]) else FMT.format(row["mean_hold_step"])
    low, high = percent(row["runs_all_held_ci_low"]), percent(row["runs_all_held_ci_high"])
    return [
        row["system"],
        label(row["controller"]),
        pm(row["return_mean"], row["return_std"]),
        percent(row["fraction_held"]),
        f"{row['runs_all_held']}/{row['n_runs']}",
        f"[{low}, {high}]",
        hold,
    ]


SWING_UP_HEADERS = (
    "system",
    "controller",
    "swing-up return",
    "episodes holding the operating point",
    "runs holding in every episode",
    "its rate: 95% CI",
    "mean hold step",
)


def swing_up_table(rows: Rows) -> list[str]:
    """Markdown rows of the swing-up table: return and hold test per controller."""
    return markdown_table(SWING_UP_HEADERS, [_swing_up_cells(row) for row in rows])


def compute(study: Study) -> dict[str, Any]:
    """The ``swing_up`` table (:func:`swing_up_summary`)."""
    return {"swing_up": swing_up_summary(study.evaluations)}


def render(report: Report) -> list[str]:
    """``## Swing-up``: the protocol, what failed, the table."""
    return [
        "",
        "## Swing-up",
        "",
        f"{SWING_UP_EPISODES} episodes per run from the seeded swing-up starts (the trainers' "
        "evaluation starts). Linear controllers are not expected to swing up. A run succeeds "
        "when it holds in every episode; 'its rate: 95% CI' is the Clopper-Pearson interval of "
        "that success rate over the runs (5 of 5 gives [48%, 100%]: a handful of seeds bounds a "
        "rate only loosely).",
        "",
        *flag_block(report.flags["swing_up"], "every learned controller swings up and holds."),
        *swing_up_table(report.tables["swing_up"]),
    ]


SECTION = Section(render, compute, SWING_UP_CHECK)
