"""The DDPG ablation's (and SAC's seeds') table and figure, from the runs' records, deterministic.

:func:`publish_ablation` reads every finished run of an ablation folder
(:mod:`leoc.experiments.ablation`), copies the records, logs and ``plan.json`` (not the
trained models) to the destination when it is another folder, and writes there::

    ablation.md             the tables: success k/n with a Wilson 95% interval per system x
                            controller x setting at the paper's budget, the optimistic "reached
                            by" counts beside, success under each model selection rule
                            re-applied to the same runs, and success against budget
    success_vs_budget.csv   one row per system, controller, setting and evaluated budget
    ablation.json           the same rows, each run's outcome at its budget, the definitions
    success_vs_budget.png   success rate against budget, one panel per system and controller

Nothing in them depends on when or where they are written (no clock, no paths), so publishing
the same records twice gives byte-identical files (a test checks the markdown and CSV).
"""

from __future__ import annotations

import shutil
import statistics
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

from leoc.experiments.ablation import (
    ABLATION_SYSTEMS,
    ALL_SETTINGS,
    GRID_CONTROLLERS,
    LOG_FILE,
    PLAN_FILE,
    RESULT_FILE,
    SETTING_LABELS,
    read_records,
    run_outcome,
)
from leoc.experiments.markdown import markdown_table
from leoc.experiments.profiles import CONTROLLER_LABELS
from leoc.experiments.stats import CONFIDENCE, wilson_interval
from leoc.io import read_json_object, write_csv_atomic, write_json_atomic, write_text_atomic
from leoc.names import controller_framework
from leoc.sb3.config import MODEL_SELECTIONS, PAPER_TOTAL_STEPS

#: Files :func:`publish_ablation` writes (the text ones are compared byte for byte by the tests).
TABLE_FILES = ("ablation.md", "success_vs_budget.csv", "ablation.json")
FIGURE_FILE = "success_vs_budget.png"
#: Columns of ``success_vs_budget.csv``.
CSV_COLUMNS = (
    "system",
    "controller",
    "setting",
    "budget",
    "successes",
    "seeds",
    "rate",
    "wilson_low",
    "wilson_high",
    "reached",
)
#: Spacing of the budget columns in the markdown's success-against-budget tables (steps).
DEFAULT_TABLE_EVERY = 1_000
MAX_LOG_BYTES = 256 * 1024
DECIMALS = 4
SUCCESS_TEXT = (
    "A run succeeds at budget T when the controller it would deliver with budget T (the actor at "
    "step T; for the settings that select, the one their model selection picks among the "
    "evaluations up to T, on the trainer's own evaluation episodes) holds the operating point "
    "in every one of its held-out swing-up episodes (starts seeded seed + 30000 + k, on leoc's "
    "system, never used for "
    "training or selection). One run per seed gives every budget up to its own: DDPG's and "
    "SAC's training do not depend on the total budget. 'Reached' counts the runs where some "
    "held-out evaluation up to T held in every episode (optimistic: a run that learnt and "
    "then forgot counts). Interval: Wilson score, 95%."
)


class CellRate(NamedTuple):
    """Success of one system x controller x setting at one budget.

    Attributes
    ----------
    system, controller, setting : str
    budget : int
        Environment steps.
    successes : int
        Seeds whose delivered controller held in every held-out episode.
    seeds : int
        Seeds that ran to at least ``budget``.
    reached : int
        Seeds with some held-out evaluation up to ``budget`` that held in every episode.
    low, high : float
        Wilson 95% interval of ``successes / seeds``.
    """

    system: str
    controller: str
    setting: str
    budget: int
    successes: int
    seeds: int
    reached: int
    low: float
    high: float

    @property
    def rate(self) -> float:
        """``successes / seeds``."""
        return self.successes / self.seeds

    def as_row(self) -> dict[str, Any]:
        """The CSV/JSON row (:data:`CSV_COLUMNS`; floats rounded to 4 decimals)."""
        return {
            "system": self.system,
            "controller": self.controller,
            "setting": self.setting,
            "budget": self.budget,
            "successes": self.successes,
            "seeds": self.seeds,
            "rate": round(self.rate, DECIMALS),
            "wilson_low": round(self.low, DECIMALS),
            "wilson_high": round(self.high, DECIMALS),
            "reached": self.reached,
        }


def _order(values: Iterable[str], preferred: Sequence[str]) -> list[str]:
    """``values`` in ``preferred``'s order, the others after it alphabetically."""
    values = set(values)
    return [v for v in preferred if v in values] + sorted(values - set(preferred))


def _cell_key(record: Mapping[str, Any]) -> tuple[str, str, str]:
    return record["system"], record["controller"], record["setting"]


def group_records(records: Iterable[Mapping[str, Any]]) -> dict[tuple[str, str, str], list]:
    """Records by ``(system, controller, setting)``, in table order, each cell by seed."""
    cells: dict[tuple[str, str, str], list] = {}
    for record in records:
        cells.setdefault(_cell_key(record), []).append(record)
    systems = _order((k[0] for k in cells), ABLATION_SYSTEMS)
    controllers = _order((k[1] for k in cells), GRID_CONTROLLERS)
    settings = _order((k[2] for k in cells), ALL_SETTINGS)
    rank = {name: i for i, name in enumerate([*systems, *controllers, *settings])}
    ordered = sorted(cells, key=lambda k: (rank[k[0]], rank[k[1]], rank[k[2]]))
    return {key: sorted(cells[key], key=lambda r: int(r["seed"])) for key in ordered}


def success_rates(records: Iterable[Mapping[str, Any]]) -> list[CellRate]:
    """Success (and reached) counts with Wilson intervals, per cell and evaluated budget.

    A cell's budgets are the evaluation steps after 0 that all its runs evaluated (runs of
    one folder share their system's budget and interval).

    Parameters
    ----------
    records : iterable of mapping
        Run records (:func:`leoc.experiments.ablation.run_cell`).

    Returns
    -------
    list of CellRate
        In table order (systems, controllers, settings as the grid lists them), budgets
        increasing.
    """
    rates = []
    for (system, controller, setting), runs in group_records(records).items():
        common = set.intersection(*({int(row["steps"]) for row in r["evaluations"]} for r in runs))
        for budget in sorted(step for step in common if step > 0):
            outcomes = [run_outcome(run, budget) for run in runs]
            successes = sum(outcome.success for outcome in outcomes)
            low, high = wilson_interval(successes, len(runs), CONFIDENCE)
            reached = sum(outcome.reached for outcome in outcomes)
            rates.append(
                CellRate(
                    system, controller, setting, budget, successes, len(runs), reached, low, high
                )
            )
    return rates


def paper_budget(system: str) -> int | None:
    """The paper's training budget of ``system`` (10k / 15k / 10k steps; None if unknown)."""
    return PAPER_TOTAL_STEPS.get(system)


def format_rate(cell: CellRate) -> str:
    """``k/n [low, high]`` with the interval to two decimals."""
    return f"{cell.successes}/{cell.seeds} [{cell.low:.2f}, {cell.high:.2f}]"


def _at(rates: Sequence[CellRate]) -> dict[tuple[str, str, str, int], CellRate]:
    return {(c.system, c.controller, c.setting, c.budget): c for c in rates}


def headline_budget(rates: Sequence[CellRate], system: str) -> int:
    """The budget of ``system``'s headline table: the paper's when every cell reached it,
    else the largest budget every cell reached."""
    cells = [c for c in rates if c.system == system]
    reached_by_all = set.intersection(
        *(
            {c.budget for c in cells if (c.controller, c.setting) == key}
            for key in {(c.controller, c.setting) for c in cells}
        )
    )
    paper = paper_budget(system)
    return paper if paper in reached_by_all else max(reached_by_all)


def headline_tables(rates: Sequence[CellRate]) -> list[str]:
    """Markdown: per system, settings x controllers, success at the paper's budget (or the
    largest all cells reached, said so) and the reached counts."""
    at = _at(rates)
    lines: list[str] = []
    for system in _order({c.system for c in rates}, ABLATION_SYSTEMS):
        budget = headline_budget(rates, system)
        cells = [c for c in rates if c.system == system]
        controllers = _order({c.controller for c in cells}, GRID_CONTROLLERS)
        settings = _order({c.setting for c in cells}, ALL_SETTINGS)
        if budget == paper_budget(system):
            lines += [f"### {system}, at the paper's budget ({budget} steps)", ""]
        else:
            lines += [
                f"### {system}, at {budget} steps (runs shorter than the paper's "
                f"{paper_budget(system)})",
                "",
            ]
        header = ["setting", *(CONTROLLER_LABELS.get(c, c) for c in controllers)]
        header += [f"reached: {CONTROLLER_LABELS.get(c, c)}" for c in controllers]
        rows = []
        for setting in settings:
            found = [at.get((system, controller, setting, budget)) for controller in controllers]
            row = [SETTING_LABELS.get(setting, setting)]
            row += [format_rate(c) if c else "-" for c in found]
            row += [f"{c.reached}/{c.seeds}" if c else "-" for c in found]
            rows.append(row)
        lines += [*markdown_table(header, rows), ""]
    return lines


#: Names of the model selection rules in the re-selection table.
SELECTION_LABELS = {
    "final": "final actor",
    "best_last_third": "best return, last third",
    "best_held": "most held, then return",
}
RESELECTION_TEXT = (
    "Each run records, at every evaluation, the return and held share of the trainer's own "
    "selection episodes beside the held-out episodes, so any model selection rule re-applies "
    "to the same runs without training again; the held-out episodes take no part in any rule. "
    "'own rule': the one the setting trains with (the success counts above). 'final actor': "
    "leoc's rule before issue 20; 'best return, last third': the authors'; 'most held, then "
    "return': the evaluation, any of the run, whose selection episodes held in the largest "
    "share, the highest return among those. The last rule was written after looking at the "
    "cart-pole and mountain-car runs, so its lead over the others there is in-sample."
)


def reselection_rows(
    records: Sequence[Mapping[str, Any]], budgets: Mapping[str, int]
) -> list[dict[str, Any]]:
    """Success counts of each model selection rule re-applied to each cell's runs, at
    ``budgets[system]`` (the headline budget): one dict per cell with ``system``,
    ``controller``, ``setting``, ``budget``, ``own_rule``, ``seeds``, ``reached`` and one count
    per rule of ``leoc.sb3.config.MODEL_SELECTIONS``."""
    rows = []
    for (system, controller, setting), runs in group_records(records).items():
        budget = budgets[system]
        if any(budget not in {int(e["steps"]) for e in run["evaluations"]} for run in runs):
            continue
        own = sorted({str(run["model_selection"]) for run in runs})
        row: dict[str, Any] = {
            "system": system,
            "controller": controller,
            "setting": setting,
            "budget": budget,
            "own_rule": "/".join(own),
            "seeds": len(runs),
            "reached": sum(run_outcome(run, budget).reached for run in runs),
        }
        for rule in MODEL_SELECTIONS:
            row[rule] = sum(run_outcome(run, budget, rule).success for run in runs)
        rows.append(row)
    return rows


def reselection_tables(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    """Markdown: per system, successes under each model selection rule (:func:`reselection_rows`)
    with their sums over the system's cells."""
    lines: list[str] = []
    for system in _order({row["system"] for row in rows}, ABLATION_SYSTEMS):
        mine = [row for row in rows if row["system"] == system]
        lines += [f"### {system}, at {mine[0]['budget']} steps", ""]
        header = ["controller", "setting", "own rule"]
        header += [SELECTION_LABELS.get(rule, rule) for rule in MODEL_SELECTIONS] + ["reached"]
        table = [
            [
                CONTROLLER_LABELS.get(row["controller"], row["controller"]),
                SETTING_LABELS.get(row["setting"], row["setting"]),
                SELECTION_LABELS.get(row["own_rule"], row["own_rule"]),
                *(f"{row[rule]}/{row['seeds']}" for rule in [*MODEL_SELECTIONS, "reached"]),
            ]
            for row in mine
        ]
        total = sum(row["seeds"] for row in mine)
        table.append(
            [
                "**all cells**",
                "",
                "",
                *(
                    f"**{sum(row[rule] for row in mine)}/{total}**"
                    for rule in [*MODEL_SELECTIONS, "reached"]
                ),
            ]
        )
        lines += [*markdown_table(header, table), ""]
    return lines


def headline_budgets(rates: Sequence[CellRate]) -> dict[str, int]:
    """:func:`headline_budget` of every system of ``rates``."""
    return {system: headline_budget(rates, system) for system in {c.system for c in rates}}


def budget_columns(budgets: Iterable[int], every: int, paper: int | None) -> list[int]:
    """The budgets shown as columns: at each multiple of ``every`` the largest evaluated
    budget up to it, the paper's budget and the largest evaluated one."""
    budgets = sorted(set(budgets))
    if not budgets:
        return []
    chosen = {budgets[-1]}
    for target in range(every, budgets[-1] + 1, every):
        below = [b for b in budgets if b <= target]
        if below:
            chosen.add(below[-1])
    if paper in budgets:
        chosen.add(paper)
    return sorted(chosen)


def budget_tables(rates: Sequence[CellRate], every: int = DEFAULT_TABLE_EVERY) -> list[str]:
    """Markdown: per system, success k/n of each controller x setting against budget."""
    at = _at(rates)
    lines: list[str] = []
    for system in _order({c.system for c in rates}, ABLATION_SYSTEMS):
        cells = [c for c in rates if c.system == system]
        columns = budget_columns({c.budget for c in cells}, every, paper_budget(system))
        lines += [f"### {system}: success against budget (steps)", ""]
        rows = []
        for controller in _order({c.controller for c in cells}, GRID_CONTROLLERS):
            for setting in _order({c.setting for c in cells}, ALL_SETTINGS):
                if not any(c.controller == controller and c.setting == setting for c in cells):
                    continue
                found = [at.get((system, controller, setting, b)) for b in columns]
                rows.append(
                    [
                        CONTROLLER_LABELS.get(controller, controller),
                        SETTING_LABELS.get(setting, setting),
                        *(f"{c.successes}/{c.seeds}" if c else "-" for c in found),
                    ]
                )
        lines += [*markdown_table(["controller", "setting", *map(str, columns)], rows), ""]
    return lines


def runs_table(records: Sequence[Mapping[str, Any]]) -> list[str]:
    """Markdown: runs, seeds and median wall time per system x controller x setting."""
    rows = []
    for (system, controller, setting), runs in group_records(records).items():
        median = statistics.median(float(r["wall_seconds"]) for r in runs)
        rows.append(
            [
                system,
                controller,
                setting,
                ", ".join(str(int(r["seed"])) for r in runs),
                str(int(runs[0]["budget"])),
                f"{median:.0f}",
            ]
        )
    header = ["system", "controller", "setting", "seeds", "budget", "median wall s"]
    return markdown_table(header, rows)


def provenance_text(records: Sequence[Mapping[str, Any]], command: str | None = None) -> str:
    """Where the runs come from: the leoc commits their records name (run counts) and the
    command recorded in the folder's plan (the last invocation on it), if any."""
    commits: dict[str, int] = {}
    for record in records:
        commit = str(record.get("versions", {}).get("leoc_commit") or "unknown")
        commits[commit] = commits.get(commit, 0) + 1
    listed = ", ".join(f"{commit} ({count} runs)" for commit, count in sorted(commits.items()))
    text = f"Runs from leoc commit {listed}."
    if command:
        text += f" Recorded command: `{command}`."
    return text


def settings_text(records: Sequence[Mapping[str, Any]]) -> str:
    """The settings the records ran, each with its label (leoc.experiments.ablation)."""
    names = _order({str(record["setting"]) for record in records}, ALL_SETTINGS)
    listed = "; ".join(f"`{name}` ({SETTING_LABELS.get(name, name)})" for name in names)
    return f"Settings (leoc.experiments.ablation): {listed}."


def markdown_report(
    records: Sequence[Mapping[str, Any]],
    rates: Sequence[CellRate],
    reselection: Sequence[Mapping[str, Any]],
    every: int = DEFAULT_TABLE_EVERY,
    command: str | None = None,
) -> str:
    """The whole ``ablation.md`` text from ``records``, their :func:`success_rates` and
    :func:`reselection_rows` (``command``: the folder's recorded invocation)."""
    algos = sorted({controller_framework(str(record["controller"])).upper() for record in records})
    learners = " and ".join(algos) or "DDPG"
    lines = [
        f"# {learners} over seeds: how often {learners} learns the swing-up",
        "",
        SUCCESS_TEXT,
        "",
        f"{settings_text(records)} {len(records)} runs.",
        "",
        provenance_text(records, command),
        "",
        "## Success at the paper's budget",
        "",
        *headline_tables(rates),
        "## Model selection re-applied to the same runs",
        "",
        RESELECTION_TEXT,
        "",
        *reselection_tables(reselection),
        "## Success against budget",
        "",
        *budget_tables(rates, every),
        "![success rate against budget](success_vs_budget.png)",
        "",
        "## Runs",
        "",
        *runs_table(records),
        "",
    ]
    return "\n".join(lines)


def cell_series(rates: Sequence[CellRate]) -> list[dict[str, Any]]:
    """One entry per system x controller x setting, with its budgets and, at each, the
    counts and the Wilson interval (the JSON's form of the CSV's rows)."""
    series: dict[tuple[str, str, str], dict[str, Any]] = {}
    for cell in rates:
        entry = series.setdefault(
            (cell.system, cell.controller, cell.setting),
            {"system": cell.system, "controller": cell.controller, "setting": cell.setting}
            | {name: [] for name in CSV_COLUMNS[3:]},
        )
        for name, value in cell.as_row().items():
            if name in entry and isinstance(entry[name], list):
                entry[name].append(value)
    return list(series.values())


def figure_curves(rates: Sequence[CellRate]) -> dict[str, dict[str, dict[str, dict]]]:
    """``system -> controller -> setting -> {"budgets", "rates"}`` for the figure."""
    curves: dict[str, dict[str, dict[str, dict]]] = {}
    for cell in rates:
        line = (
            curves.setdefault(cell.system, {})
            .setdefault(cell.controller, {})
            .setdefault(cell.setting, {"budgets": [], "rates": []})
        )
        line["budgets"].append(cell.budget)
        line["rates"].append(cell.rate)
    return curves


def figure_caption(rates: Sequence[CellRate]) -> str:
    """What the figure's lines are, with the seed counts it holds."""
    from leoc.evaluation.plots.ablation import DODGE

    counts = sorted({cell.seeds for cell in rates})
    seeds = "/".join(str(n) for n in counts)
    offset = DODGE * (len({cell.setting for cell in rates}) - 1) / 2.0
    dodge = (
        f"Lines are offset vertically by up to +/-{offset:.3f} so that settings at the same "
        "rate stay visible; "
        if offset > 0
        else ""
    )
    return (
        f"Fraction of seeds ({seeds} per line) whose delivered controller held the operating "
        f"point in all held-out swing-up episodes, against the training budget. {dodge}"
        "Grey vertical line: the paper's budget."
    )


def write_tables(
    dest: str | Path,
    records: Sequence[Mapping[str, Any]],
    every: int = DEFAULT_TABLE_EVERY,
    command: str | None = None,
) -> Path:
    """Write :data:`TABLE_FILES` and the figure into ``dest`` from ``records`` (``command``:
    the folder's recorded invocation, quoted in the markdown), and the relevance report
    (:mod:`leoc.experiments.relevance_report`) when hybrid records carry ``lqr_agreement``;
    returns the markdown's path."""
    from leoc.evaluation.plots.ablation import plot_success_vs_budget

    out = Path(dest)
    out.mkdir(parents=True, exist_ok=True)
    rates = success_rates(records)
    reselection = reselection_rows(records, headline_budgets(rates))
    rows = [cell.as_row() for cell in rates]
    write_csv_atomic(out / "success_vs_budget.csv", rows, CSV_COLUMNS)
    runs = [
        {
            "key": r["key"],
            "budget": int(r["budget"]),
            "model_selection": r["model_selection"],
            "outcome_at_budget": run_outcome(r, int(r["budget"]))._asdict(),
            "wall_seconds": round(float(r["wall_seconds"]), 1),
        }
        for records_of_cell in group_records(records).values()
        for r in records_of_cell
    ]
    summary = {
        "definition": SUCCESS_TEXT,
        "settings": {
            name: SETTING_LABELS.get(name, name)
            for name in _order({str(r["setting"]) for r in records}, ALL_SETTINGS)
        },
        "paper_budgets": {s: paper_budget(s) for s in sorted({c.system for c in rates})},
        "cells": cell_series(rates),
        "reselection": reselection,
        "runs": runs,
    }
    write_json_atomic(out / "ablation.json", summary, indent=1)
    markdown = out / "ablation.md"
    write_text_atomic(markdown, markdown_report(records, rates, reselection, every, command))
    paper_budgets = {s: b for s in {c.system for c in rates} if (b := paper_budget(s))}
    plot_success_vs_budget(
        figure_curves(rates),
        out / FIGURE_FILE,
        paper_budgets,
        SETTING_LABELS,
        CONTROLLER_LABELS,
        figure_caption(rates),
    )
    from leoc.experiments.relevance_report import PILCO_FOLDER as PILCO
    from leoc.experiments.relevance_report import pilco_relevance_records, write_relevance_report

    write_relevance_report(out, [*records, *pilco_relevance_records(out / PILCO)], command)
    return markdown


def _copy_records(source: Path, target: Path) -> None:
    """The plan, each run's record and small log, and the PILCO hybrids' relevance records,
    from ``source`` into ``target``."""
    from leoc.experiments.relevance_report import PILCO_FOLDER, pilco_relevance_records

    pilco_relevance_records(source / PILCO_FOLDER, write_to=target / PILCO_FOLDER)
    if (source / PLAN_FILE).is_file():
        write_text_atomic(target / PLAN_FILE, (source / PLAN_FILE).read_text())
    for path in sorted(source.glob(f"runs/*/*/*/seed*/{RESULT_FILE}")):
        copy = target / path.parent.relative_to(source)
        copy.mkdir(parents=True, exist_ok=True)
        write_text_atomic(copy / RESULT_FILE, path.read_text())
        log = path.parent / LOG_FILE
        if log.is_file() and log.stat().st_size <= MAX_LOG_BYTES:
            shutil.copyfile(log, copy / LOG_FILE)


def publish_ablation(
    source: str | Path, dest: str | Path | None = None, every: int = DEFAULT_TABLE_EVERY
) -> Path:
    """Publish an ablation folder: its records (and the relevance records of the PILCO hybrids
    in its ``pilco`` folder) copied to ``dest`` (unless it is ``source``, or None), and the
    tables and figure written there from them.

    Parameters
    ----------
    source : path
        An ablation folder (:mod:`leoc.experiments.ablation`), or a published one.
    dest : path, optional
        Where to publish (default: ``source`` itself). The trained models stay behind.
    every : int
        Spacing of the budget columns of the markdown tables (environment steps); the CSV and
        JSON hold every evaluated budget.

    Returns
    -------
    Path
        ``dest/ablation.md``.

    Raises
    ------
    FileNotFoundError
        When ``source`` holds no finished run.
    ValueError
        When ``dest`` lies inside ``source`` (but is not ``source``).
    """
    source_path = Path(source).resolve()
    target = source_path if dest is None else Path(dest).resolve()
    if target != source_path and source_path in target.parents:
        raise ValueError(f"dest: expected a folder outside {str(source)!r}, found {str(dest)!r}")
    records = read_records(source_path)
    if not records:
        raise FileNotFoundError(f"source: no finished run ({RESULT_FILE}) in {str(source)!r}")
    if target != source_path:
        _copy_records(source_path, target)
    plan = read_json_object(source_path / PLAN_FILE, print, "ablation plan") or {}
    return write_tables(target, records, every, plan.get("command"))
