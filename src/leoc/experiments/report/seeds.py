"""The report's seed statistics: IQM and bootstrap interval over seeds of the learned
controllers, and the probability that each hybrid beats its baseline."""

from __future__ import annotations

from collections import defaultdict
from typing import Any

from leoc.experiments.layout import Evaluations
from leoc.experiments.markdown import markdown_table
from leoc.experiments.profiles import LINEAR_CONTROLLERS
from leoc.experiments.report.base import (
    FMT,
    Report,
    Rows,
    Section,
    Study,
    interval,
    label,
    ordered,
)
from leoc.experiments.stats import MIN_RUNS_FOR_INTERVAL, probability_of_improvement, seed_summary
from leoc.names import CONTROLLERS, FRAMEWORKS, controller_framework, parse_controller


def first_hold_seconds(run: dict[str, Any]) -> float | None:
    """Interaction time of the first evaluation at which every episode held (None: never)."""
    curve = run.get("curve") or {}
    for seconds, held in zip(curve.get("seconds", []), curve.get("held_fraction", []), strict=True):
        if held >= 1.0:
            return float(seconds)
    return None


SEED_QUANTITIES = {
    "final return": lambda run: run["curve"]["returns"][-1] if run.get("curve") else None,
    "interaction time to first hold [s]": first_hold_seconds,
    "impulse steady-state error": lambda run: run["responses"]["impulse"]["metrics"][
        "steady_state_error"
    ],
    "impulse peak deviation": lambda run: run["responses"]["impulse"]["metrics"]["peak_deviation"],
    "impulse settling time [steps]": lambda run: run["responses"]["impulse"]["metrics"][
        "settling_time"
    ],
}
IMPROVEMENT_QUANTITIES = ("final return", "interaction time to first hold")


def seed_statistics(evaluations: Evaluations) -> Rows:
    """Rows: system, controller, quantity, IQM over seeds and its 95 % stratified-bootstrap
    interval (none with fewer than three seeds; the note says so), seeds used and missing (a
    run that never held or never settled has no value)."""
    rows = []
    for system, by_controller in evaluations.items():
        for controller in ordered(by_controller):
            if controller in LINEAR_CONTROLLERS:
                continue
            runs = by_controller[controller]
            for quantity, value_of in SEED_QUANTITIES.items():
                summary = seed_summary([value_of(run) for run in runs])
                rows.append(
                    {
                        "system": system,
                        "controller": controller,
                        "quantity": quantity,
                        **summary._asdict(),
                    }
                )
    return rows


def _improvement_scores(
    quantity: str, hybrid: list[dict[str, Any]], baseline: list[dict[str, Any]]
) -> tuple[list[float], list[float]] | None:
    """Scores (higher is better) of both groups for ``quantity``, or None when a run lacks
    them. Interaction time: minus the seconds to the first hold; a run that never held ranks
    below every run that did, and ties with the others that never did (P(X > Y) depends on ranks
    only, so any value below all the others serves)."""
    if quantity == "final return":
        final = SEED_QUANTITIES["final return"]
        scores = [final(run) for run in hybrid], [final(run) for run in baseline]
        return None if None in scores[0] + scores[1] else scores
    runs = hybrid + baseline
    if any(not run.get("curve") for run in runs):
        return None
    never = -1.0 - max(max(run["curve"]["seconds"], default=0.0) for run in runs)

    def score(run: dict[str, Any]) -> float:
        seconds = first_hold_seconds(run)
        return never if seconds is None else -seconds

    return [score(run) for run in hybrid], [score(run) for run in baseline]


def framework_hybrids(framework: str) -> tuple[str, ...]:
    """The hybrids of ``framework`` that ``leoc reproduce`` knows, in report order: one per
    relevance design (the paper's, the ROA, the Lyapunov relevance where the learner has it)."""
    return tuple(
        name
        for name in CONTROLLERS
        if controller_framework(name) == framework and parse_controller(name).hybrid
    )


def improvement_rows(evaluations: Evaluations) -> Rows:
    """Probability that each hybrid (every relevance design: :func:`framework_hybrids`) beats
    its framework's baseline: a higher final return, and the first hold after less interaction
    time (the paper's claim (ii)); :func:`~leoc.experiments.stats.probability_of_improvement`."""
    rows = []
    for system, by_controller in evaluations.items():
        for framework in FRAMEWORKS:
            baseline = by_controller.get(f"{framework}_baseline")
            for hybrid_name in framework_hybrids(framework):
                hybrid = by_controller.get(hybrid_name)
                if not hybrid or not baseline:
                    continue
                for quantity in IMPROVEMENT_QUANTITIES:
                    scores = _improvement_scores(quantity, hybrid, baseline)
                    if scores is None:
                        continue
                    estimate = probability_of_improvement(*scores)
                    rows.append(
                        {
                            "system": system,
                            "framework": framework,
                            "hybrid": hybrid_name,
                            "quantity": quantity,
                            **estimate._asdict(),
                        }
                    )
    return rows


SEED_HEADERS = (
    "system",
    "controller",
    "quantity",
    "IQM",
    "95% CI",
    "seeds used",
    "seeds without a value",
)
IMPROVEMENT_HEADERS = (
    "system",
    "hybrid",
    "baseline",
    "P(higher final return)",
    "95% CI",
    "P(first hold sooner)",
    "95% CI",
)


def seed_table(rows: Rows) -> list[str]:
    """Markdown rows of the seed statistics: IQM and 95% bootstrap interval per quantity."""
    table = [
        [
            row["system"],
            label(row["controller"]),
            row["quantity"],
            "-" if row["iqm"] is None else FMT.format(row["iqm"]),
            interval(row["ci_low"], row["ci_high"], row["note"]),
            str(row["n"]),
            str(row["n_missing"]),
        ]
        for row in rows
    ]
    return markdown_table(SEED_HEADERS, table)


def improvement_table(rows: Rows) -> list[str]:
    """Markdown rows of the probability that each hybrid beats its baseline."""
    by_pair: dict[tuple[str, str, str], dict[str, dict[str, Any]]] = defaultdict(dict)
    for row in rows:
        key = (row["system"], row["hybrid"], f"{row['framework']}_baseline")
        by_pair[key][row["quantity"]] = row
    table = []
    for (system, hybrid, baseline), found in by_pair.items():
        cells = [system, label(hybrid), label(baseline)]
        for quantity in IMPROVEMENT_QUANTITIES:
            row = found.get(quantity)
            if row is None:
                cells += ["-", "-"]
                continue
            cells.append("-" if row["probability"] is None else f"{row['probability']:.2f}")
            cells.append(interval(row["ci_low"], row["ci_high"], row["note"]))
        table.append(cells)
    return markdown_table(IMPROVEMENT_HEADERS, table)


def compute(study: Study) -> dict[str, Any]:
    """The ``seeds`` (:func:`seed_statistics`) and ``improvements`` (:func:`improvement_rows`)
    tables."""
    evaluations = study.evaluations
    return {"seeds": seed_statistics(evaluations), "improvements": improvement_rows(evaluations)}


def _few_seeds_lines(n_seeds: int) -> list[str]:
    """What the intervals are worth with fewer than four seeds (nothing to say with more)."""
    if n_seeds < MIN_RUNS_FOR_INTERVAL:
        return [
            f"With {n_seeds} seed(s) there are no intervals (at least "
            f"{MIN_RUNS_FOR_INTERVAL} are needed); the IQM of one value is that value.",
            "",
        ]
    if n_seeds < 4:
        return [
            f"With {n_seeds} seeds the IQM trims nothing (it is the mean) and the bootstrap has "
            "few distinct resamples: read the intervals as rough.",
            "",
        ]
    return []


def render(report: Report) -> list[str]:
    """``## Seed statistics``: IQM and intervals, then the probabilities of improvement."""
    return [
        "",
        "## Seed statistics",
        "",
        "Interquartile mean (IQM) over seeds and its 95% stratified-bootstrap confidence "
        "interval (Agarwal et al. 2021, 'Deep RL at the edge of the statistical precipice'; "
        "`leoc.experiments.stats`). 'final return': the last evaluation of the learning curve; "
        "'interaction time to first hold': the first evaluation at which every episode held "
        "(a seed that never held has no value and is counted as without one).",
        "",
        *_few_seeds_lines(len(report.study.meta.get("seeds", []))),
        *seed_table(report.tables["seeds"]),
        "",
        "Probability that a run of the hybrid beats a run of its baseline (Mann-Whitney, "
        "ties count half; 95% stratified-bootstrap interval): a higher final return, and the "
        "first hold after less interaction time, a run that never held ranking below every run "
        "that did (the paper's claim that the hybrid needs similar or less interaction time).",
        "",
        *improvement_table(report.tables["improvements"]),
    ]


SECTION = Section(render, compute)
