"""The report's robustness protocol: per category of perturbation the share of episodes each
controller holds (``evaluation.json``'s ``robustness_protocol``,
:func:`leoc.experiments.evaluators.evaluate_robustness_protocol`), over seeds, and one figure
per system (``robustness_protocol_SYSTEM.png``)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from leoc.evaluation.robustness_protocol import (
    CATEGORY_NAMES,
    PROTOCOL_START_KINDS,
    CategoryResult,
    LevelResult,
    ProtocolResult,
)
from leoc.experiments.layout import Evaluations
from leoc.experiments.markdown import markdown_table
from leoc.experiments.report.base import FMT, Report, Rows, Section, Study, label, ordered
from leoc.experiments.stats import (
    MIN_RUNS_FOR_INTERVAL,
    improvement_verdict,
    interval_verdict,
    stratified_bootstrap_ci,
)
from leoc.names import CONTROLLER_KINDS, LINEAR, parse_controller

KEY = "robustness_protocol"
"""The runs' entry the section reads (``evaluation.json``)."""
SCORE = "robustness"
"""The column of the categories' mean (the robustness score)."""
OPERATING = PROTOCOL_START_KINDS[0]
"""The start kind from the operating region (where a hybrid's flat top can make it its LQR)."""
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
        runs = {label(c): len(seeds) for c, seeds in by_controller.items()}
        written.append(plot_protocol_scores(results, study.out / figure_name(system), keys, runs))
    return written


def _cell(spread: dict[str, float]) -> str:
    """``median [least, largest]`` (the median alone when they agree)."""
    if spread["min"] == spread["max"]:
        return f"{spread['median']:.2f}"
    return f"{spread['median']:.2f} [{spread['min']:.2f}, {spread['max']:.2f}]"


def protocol_table(rows: Rows, study: str | None = None) -> list[str]:
    """Markdown rows of one system's table: per controller, every category's score and the
    robustness score; with ``study``, two first columns name it and the row's system (several
    studies' in one table: :func:`leoc.experiments.markdown.stacked_tables`)."""
    names = [name for name in CATEGORY_NAMES if name in rows[0]["scores"]] if rows else []
    names = names or list(CATEGORY_NAMES)
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
    if study is None:
        return markdown_table(headers, table)
    leading = [[study, row["system"], *cells] for row, cells in zip(rows, table, strict=True)]
    return markdown_table(["study", "system", *headers], leading)


def _maxima(row: dict[str, Any]) -> str:
    """The maximum level of each category (the end of its sweep)."""
    levels = row["max_levels"]
    return ", ".join(
        f"{name.replace('_', ' ')} {FMT.format(levels[name])}"
        for name in CATEGORY_NAMES
        if name in levels
    )


def _system_lines(system: str, rows: Rows, verdicts: Rows) -> list[str]:
    constants = ", ".join(rows[0]["max_levels"]["constants"])
    lines = [
        "",
        f"### {system}",
        "",
        f"Sweeps up to: {_maxima(rows[0])} (parameter errors of {constants}, one at a time).",
        "",
        *protocol_table(rows),
        "",
        f"![Robustness protocol: {system}]({figure_name(system)})",
    ]
    if verdicts:
        lines += [
            "",
            VERDICT_METHOD,
            "",
            *verdict_sentences(verdicts),
            "",
            *verdict_table(verdicts),
        ]
    return lines


def reference_names(controller: str, available: Any) -> tuple[str | None, str | None]:
    """A hybrid's references in a study: its LQR (``linear_LEARNER``, the LQR at the learner's
    control period, else ``linear``) and its baseline (``LEARNER_baseline``); None where the
    study has no such runs."""
    learner = parse_controller(controller).learner
    lqr = next((name for name in (f"{LINEAR}_{learner}", LINEAR) if name in available), None)
    baseline = f"{learner}_baseline"
    return lqr, baseline if baseline in available else None


def _mean_of_resamples(resamples: np.ndarray) -> np.ndarray:
    return resamples.mean(axis=(1, 2))


def _versus_lqr(hybrid: list[float], lqr: float) -> dict[str, Any]:
    """The hybrid's mean share over seeds minus its LQR's (both from the operating region),
    with a 95% stratified-bootstrap interval over the hybrid's seeds (the LQR is designed, not
    trained: one value), and the verdict: ``above``/``below`` where the interval excludes 0,
    ``equal`` where every seed scores the LQR's score, else ``unresolved``; ``n < 3`` seeds
    give no interval."""
    differences = np.asarray(hybrid, dtype=float) - lqr
    low = high = None
    if len(differences) >= MIN_RUNS_FOR_INTERVAL:
        low, high = stratified_bootstrap_ci(differences, _mean_of_resamples)
    return {
        "difference": float(differences.mean()),
        "ci_low": low,
        "ci_high": high,
        "verdict": interval_verdict(differences, low, high, 0.0),
    }


def _matched_levels(
    hybrid: ProtocolResult, lqr: ProtocolResult, name: str = SCORE
) -> list[tuple[Any, Any]] | None:
    """The (hybrid level, LQR level) pairs of category ``name`` (or of every category), in
    sweep order; None where the two did not run the same sweep (a category, a level or a
    constant missing or different)."""
    theirs = {category.name: category for category in lqr.categories}
    pairs = []
    for category in hybrid.categories:
        if name not in (SCORE, category.name):
            continue
        reference = theirs.get(category.name)
        if reference is None or len(reference.levels) != len(category.levels):
            return None
        for mine, its in zip(category.levels, reference.levels, strict=True):
            if mine.constant != its.constant or not math.isclose(mine.level, its.level):
                return None
            pairs.append((mine, its))
    return pairs


def _same_episodes(hybrid: ProtocolResult, lqr: ProtocolResult, kind: str) -> bool:
    """Whether ``hybrid`` held exactly the episodes ``lqr`` held from ``kind`` starts, at every
    level of every category (False where the sweeps differ)."""
    pairs = _matched_levels(hybrid, lqr)
    return pairs is not None and all(
        mine.held.get(kind) == its.held.get(kind) for mine, its in pairs
    )


LOST_COUNTS = ("lost", "where_lqr_loses", "operating_lost", "operating_where_lqr_loses")
"""The lost-episode counts of :func:`_lost_where_lqr_loses`, every start first, then those from
the operating region."""


def _lost(hybrid: ProtocolResult, lqr: ProtocolResult, name: str) -> tuple[int, ...] | None:
    """Episodes ``hybrid`` lost in category ``name`` (or every category) and how many of those
    were at levels where ``lqr`` lost an operating-region episode too, from every start and
    then from the operating region (:data:`LOST_COUNTS`, one walk of the levels); None where
    the two did not run the same sweep."""
    pairs = _matched_levels(hybrid, lqr, name)
    if pairs is None:
        return None
    counts = [0, 0, 0, 0]
    for mine, its in pairs:
        lqr_held, lqr_total = its.held_count(OPERATING)
        lqr_loses = lqr_held < lqr_total
        for offset, start_kind in ((0, None), (2, OPERATING)):
            held, total = mine.held_count(start_kind)
            counts[offset] += total - held
            counts[offset + 1] += (total - held) if lqr_loses else 0
    return tuple(counts)


def _lost_where_lqr_loses(
    results: list[ProtocolResult], lqr: list[ProtocolResult], name: str
) -> dict[str, int] | None:
    """:data:`LOST_COUNTS` summed over the hybrid's seeds (:func:`_lost`); None without a
    single LQR run on the same sweep."""
    if len(lqr) != 1:
        return None
    counts = [_lost(result, lqr[0], name) for result in results]
    if any(count is None for count in counts):
        return None
    return {key: sum(count[index] for count in counts) for index, key in enumerate(LOST_COUNTS)}


def protocol_verdicts(evaluations: Evaluations) -> Rows:
    """Rows, per system, hybrid and category (and the robustness score): whether the hybrid
    is at least as robust as its LQR (from the operating region, where the claim is made: the
    LQR cannot swing up) and more robust than its baseline (every start), with intervals over
    seeds (:func:`reference_names` names both); ``operating_as_lqr`` where the hybrid held the
    LQR's very episodes from the operating region at every level on every seed (the signature
    of a comparison that holds by construction: the state never left the hybrid's flat top)."""
    rows = []
    for system, by_controller in protocol_results(evaluations).items():
        for controller, results in by_controller.items():
            if not parse_controller(controller).hybrid:
                continue
            lqr, baseline = reference_names(controller, by_controller)
            as_lqr = (
                lqr is not None
                and len(by_controller[lqr]) == 1
                and all(_same_episodes(r, by_controller[lqr][0], OPERATING) for r in results)
            )
            first = results[0].scores()
            for name in [*(n for n in CATEGORY_NAMES if n in first), SCORE]:
                mine = [_score(result, name) for result in results]
                row = {
                    "system": system,
                    "controller": controller,
                    "category": name,
                    "lqr": lqr,
                    "baseline": baseline,
                    "versus_lqr": None,
                    "versus_baseline": None,
                    "operating_as_lqr": as_lqr,
                    "lost": None,
                }
                if lqr is not None:
                    reference = by_controller[lqr]
                    row["lost"] = _lost_where_lqr_loses(results, reference, name)
                    value = float(np.mean([_score(r, name, OPERATING) for r in reference]))
                    near = [_score(result, name, OPERATING) for result in results]
                    row["versus_lqr"] = _versus_lqr(near, value)
                if baseline is not None:
                    theirs = [_score(r, name) for r in by_controller[baseline]]
                    row["versus_baseline"] = improvement_verdict(mine, theirs)
                rows.append(row)
    return rows


def _score(result: ProtocolResult, name: str, start_kind: str | None = None) -> float:
    """Category ``name``'s score (or the robustness score) from ``start_kind`` (None: all)."""
    return result.score(start_kind) if name == SCORE else result.scores(start_kind)[name]


def _with_interval(value: float, low: float | None, high: float | None, signed: bool) -> str:
    """``value [low, high]`` to two decimals (signed: with its sign), the value alone without
    an interval."""
    form = "{:+.2f}" if signed else "{:.2f}"
    if low is None or high is None:
        return form.format(value)
    return f"{form.format(value)} [{form.format(low)}, {form.format(high)}]"


def verdict_table(rows: Rows) -> list[str]:
    """Markdown rows of one system's verdicts: per hybrid and category, the score minus its
    LQR's and P(hybrid > baseline), each with its interval and verdict."""
    headers = [
        "hybrid",
        "category",
        "operating region, minus its LQR",
        "verdict",
        "P(> its baseline), all starts",
        "verdict",
        "lost where its LQR loses (from the operating region)",
    ]
    table = []
    for row in rows:
        lqr, baseline = row["versus_lqr"], row["versus_baseline"]
        table.append(
            [
                label(row["controller"]),
                row["category"].replace("_", " "),
                "-"
                if lqr is None
                else _with_interval(lqr["difference"], lqr["ci_low"], lqr["ci_high"], True),
                "-" if lqr is None else lqr["verdict"],
                "-"
                if baseline is None
                else _with_interval(
                    baseline["probability"], baseline["ci_low"], baseline["ci_high"], False
                ),
                "-" if baseline is None else baseline["verdict"],
                _lost_cell(row["lost"]),
            ]
        )
    return markdown_table(headers, table)


def _verdict_pair(row: dict[str, Any]) -> str:
    """``against its LQR / against its baseline`` (``-`` where that reference is missing)."""
    lqr, baseline = row["versus_lqr"], row["versus_baseline"]
    return (
        f"{'-' if lqr is None else lqr['verdict']} / "
        f"{'-' if baseline is None else baseline['verdict']}"
    )


def verdict_summary_table(rows: Rows, study: str | None = None) -> list[str]:
    """Markdown rows of :func:`protocol_verdicts`' verdicts in one line per system and hybrid:
    every category's and the robustness score's cell is ``against its LQR / against its
    baseline`` (from the operating region against the LQR, every start against the baseline;
    ``–`` for a category the hybrid was not swept in). The columns are every category of
    :data:`CATEGORY_NAMES` whatever ``rows`` hold, so several studies' tables stack; with
    ``study``, a first column names it (:func:`leoc.experiments.markdown.stacked_tables`)."""
    names = [*CATEGORY_NAMES, SCORE]
    cells: dict[tuple[str, str], dict[str, str]] = {}
    for row in rows:
        cells.setdefault((row["system"], row["controller"]), {})[row["category"]] = _verdict_pair(
            row
        )
    headers = ["system", "hybrid", *(name.replace("_", " ") for name in names)]
    table = [
        [system, label(controller), *(found.get(name, "–") for name in names)]
        for (system, controller), found in cells.items()
    ]
    if study is None:
        return markdown_table(headers, table)
    return markdown_table(["study", *headers], [[study, *cells_] for cells_ in table])


def _lost_cell(lost: dict[str, int] | None) -> str:
    """``M of N (m of n)``: of the hybrid's N lost episodes, the M at levels where its LQR lost
    too; in brackets the same of the n it lost from the operating region."""
    if lost is None:
        return "-"
    near = lost.get("operating_lost")
    whole = f"{lost['where_lqr_loses']} of {lost['lost']}"
    return whole if near is None else f"{whole} ({lost['operating_where_lqr_loses']} of {near})"


def _categories_where(rows: Rows, comparison: str, verdict: str) -> list[str]:
    """The categories of ``rows`` whose ``comparison`` has a verdict starting with ``verdict``."""
    return [
        row["category"].replace("_", " ")
        for row in rows
        if row[comparison]["verdict"].startswith(verdict)
    ]


def verdict_sentences(rows: Rows) -> list[str]:
    """Per hybrid: in how many categories it is at least as robust as its LQR (not ``below``)
    and more robust than its baseline (``above``), naming the exceptions; how many of its lost
    episodes were at levels where its LQR lost too; and whether from the operating region it
    held its LQR's very episodes (by construction for an ROA hybrid, evidence otherwise)."""
    lines = []
    for controller in dict.fromkeys(row["controller"] for row in rows):
        mine = [row for row in rows if row["controller"] == controller and row["category"] != SCORE]
        parts = []
        if mine[0]["versus_lqr"] is not None:
            below = _categories_where(mine, "versus_lqr", "below")
            parts.append(
                f"at least as robust as its LQR ({label(mine[0]['lqr'])}) in "
                f"{len(mine) - len(below)} of {len(mine)} categories"
                + (f" (below in {', '.join(below)})" if below else "")
            )
        if mine[0]["versus_baseline"] is not None:
            above = _categories_where(mine, "versus_baseline", "above")
            parts.append(
                f"more robust than its baseline in {len(above)} of {len(mine)}"
                + (f" ({', '.join(above)})" if above else "")
            )
        total = [
            row for row in rows if row["controller"] == controller and row["category"] == SCORE
        ]
        lost = total[0]["lost"] if total else None
        if lost is not None and lost["lost"]:
            parts.append(
                f"{lost['where_lqr_loses']} of its {lost['lost']} lost episodes were at levels "
                "where its LQR lost operating-region episodes too, "
                f"{lost['operating_where_lqr_loses']} of the {lost['operating_lost']} it lost "
                "from the operating region"
            )
        if mine[0]["operating_as_lqr"]:
            flat = parse_controller(controller).relevance == CONTROLLER_KINDS["hybrid_roa"]
            parts.append(
                "from the operating region it held its LQR's very episodes at every level on "
                "every seed: "
                + (
                    "there the comparison holds by construction (its flat top)"
                    if flat
                    else "evidence, not construction (its relevance is below 1 off a)"
                )
            )
        if parts:
            lines.append(f"- {label(controller)}: {'; '.join(parts)}.")
    return lines


VERDICT_METHOD = (
    "Does the hybrid keep its LQR's robustness and beat its baseline? Per category, the "
    "hybrid's mean share held from the operating region over seeds minus its LQR's (the LQR at "
    "the hybrid's control period; the claim is made near the operating point, and the "
    "pendulum's and the cart-pole's LQR cannot swing up), with a 95% stratified-bootstrap "
    "interval over the hybrid's seeds; and "
    "the probability that a hybrid seed scores above a baseline seed from every start (Agarwal "
    "et al. 2021), with its 95% interval. Verdicts: above or below where the interval excludes "
    "0 (or 0.5), unresolved where it does not, equal where every score is the same; with fewer "
    "than 3 seeds no interval (n < 3). An ROA hybrid that held its LQR's very episodes from "
    "the operating region is its LQR there by construction (its states stayed on its flat "
    "top), and is said so; a paper-relevance hybrid that did (r < 1 off a) is evidence. Lost "
    "where its LQR loses: of the hybrid's lost episodes (every start, summed over seeds), "
    "those at levels where its LQR lost an operating-region episode too; in brackets the same "
    "of the episodes it lost from the operating region. Each sweep ends where "
    "the LQR holds none, and near the operating point the hybrid is (nearly) its LQR, so "
    "losses there are the design's, not the learned part's (a coincidence of levels, not a "
    "measured cause)."
)
"""The verdicts' opening paragraph."""


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
    return {
        "robustness_protocol": protocol_summary(study.evaluations),
        "robustness_protocol_verdicts": protocol_verdicts(study.evaluations),
    }


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
        verdicts = report.tables.get("robustness_protocol_verdicts", [])
        lines += _system_lines(
            system,
            [row for row in rows if row["system"] == system],
            [row for row in verdicts if row["system"] == system],
        )
    return lines


SECTION = Section(render, compute)
