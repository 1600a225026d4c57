"""The headline table: each claim of the paper, its verdict in two published studies and the
number that decides it, generated from the studies' ``results.json``.

Each row is one of the report's checks (:mod:`leoc.experiments.report`: the same ``Check``
the report's summary makes, one home for each threshold) applied to one kind of controller:
the hybrids with the paper's relevance, those with the ROA relevance, or the baselines; the
LQR rows stay in every table as the references. The verdict is **holds** when every case
checked passes, **fails** when none does, **partly** otherwise, and *not measured* when the
study has no case (a study published before the check existed). Claim (ii) is read from the
probability of improvement of the interaction time to the first hold, hybrid against its
baseline: it holds when no pair is resolved below 0.5.

``leoc headline`` prints the table, or writes it between the :data:`BEGIN` and :data:`END`
markers of a markdown file (the README); a test checks that the committed README equals what
the command writes from the committed studies.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

from leoc.experiments.markdown import markdown_table, stacked_tables
from leoc.experiments.stats import is_missing
from leoc.names import LINEAR, parse_controller

__all__ = [
    "BEGIN",
    "CLAIMS",
    "CROSS_STUDY_TABLES",
    "END",
    "PROVED_BEGIN",
    "PROVED_END",
    "ROBUSTNESS_BEGIN",
    "ROBUSTNESS_END",
    "VERDICTS_BEGIN",
    "VERDICTS_END",
    "HeadlineClaim",
    "claim_cell",
    "headline_lines",
    "load_results",
    "markers",
    "proved_region_lines",
    "robustness_lines",
    "robustness_verdict_lines",
    "study_heading",
    "write_headline",
]


def markers(name: str) -> tuple[str, str]:
    """The lines between which :func:`write_headline` writes the table called ``name``."""
    begin = f"<!-- {name}: begin (written by `leoc headline`; edit the code, not this table) -->"
    return begin, f"<!-- {name}: end -->"


BEGIN, END = markers("headline")
"""The claims table's lines (:func:`markers` of ``headline``)."""
PROVED_BEGIN, PROVED_END = markers("proved regions")
"""The cross-study proved-region table's lines (:func:`proved_region_lines`)."""
ROBUSTNESS_BEGIN, ROBUSTNESS_END = markers("robustness scores")
"""The cross-study robustness-score table's lines (:func:`robustness_lines`)."""
VERDICTS_BEGIN, VERDICTS_END = markers("robustness verdicts")
"""The cross-study robustness-verdict table's lines (:func:`robustness_verdict_lines`)."""
SHOWN_MISS = 1
"""Failures named per cell (the biggest; the study's report lists every one)."""
IMPROVEMENT = "interaction time to first hold"
"""The probability-of-improvement quantity of claim (ii)."""
EVEN = 0.5
"""P(hybrid first) of two controllers that hold equally soon."""


class HeadlineClaim(NamedTuple):
    """One row: the ``claim`` as the table states it, the report check ``check`` (a key of
    ``results.json``'s ``checks``, or ``"improvements"`` for claim (ii)) and the controllers
    whose cases count: ``"paper"`` and ``"roa"`` (hybrids of that relevance), ``"baseline"``,
    ``"hybrid"`` (every hybrid), ``"learned"`` (every controller but the LQRs)."""

    claim: str
    check: str
    kind: str


CLAIMS = (
    HeadlineClaim(
        "(i) near a the hybrid responds as its LQR: impulse and step, each metric within 1% "
        "(paper relevance)",
        "responses",
        "paper",
    ),
    HeadlineClaim(
        "(i) the same, ROA relevance (r = 1 on the LQR's proved set: a response that stays in "
        "it equals the LQR's by construction)",
        "responses",
        "roa",
    ),
    HeadlineClaim(
        "(i) the hybrid holds every start of its LQR's certified region (paper relevance)",
        "roa",
        "paper",
    ),
    HeadlineClaim("(i) the same, ROA relevance", "roa", "roa"),
    HeadlineClaim(
        "(i) the trained hybrid proves its LQR's region of attraction (interval proof; paper "
        "relevance)",
        "proved_regions",
        "paper",
    ),
    HeadlineClaim("(i) the same, ROA relevance", "proved_regions", "roa"),
    HeadlineClaim(
        "(ii) the hybrid needs no more interaction than its baseline to hold the swing-up: "
        "P(hybrid holds first) over seeds, 95% interval",
        "improvements",
        "hybrid",
    ),
    HeadlineClaim(
        "(iii) the baselines show steady-state error: after the impulse and the step they end "
        "off the LQR's end point (as the report compares metrics: by more than 1%)",
        "baseline_offsets",
        "baseline",
    ),
    HeadlineClaim(
        "every learned controller swings up and holds in every held-out episode",
        "swing_up",
        "learned",
    ),
    HeadlineClaim(
        "(iv) the hybrid is at least as robust as its LQR to mass and gravity x0.5-x5: at "
        "every scale it stabilises the LQR's share of episodes or more (paper relevance)",
        "robustness",
        "paper",
    ),
    HeadlineClaim("(iv) the same, ROA relevance", "robustness", "roa"),
)
"""The table's rows, in order (at most 12 with the header, as the README asks)."""


def _wanted(kind: str) -> Callable[[str], bool]:
    """Whether a controller's cases count for ``kind``; the LQRs always stay (references)."""

    def wanted(controller: str) -> bool:
        name = parse_controller(controller)
        if name.learner == LINEAR:
            return True
        if kind == "baseline":
            return not name.hybrid
        if kind == "hybrid":
            return name.hybrid
        if kind == "learned":
            return True
        return name.relevance == kind

    return wanted


def _checks() -> dict[str, Any]:
    """The report's checks by the name :data:`CLAIMS` gives them (imported here: the report
    pulls in matplotlib); claim (iv) asks for at least the LQR's robustness, so its check is
    the robustness section's deficit check, not its two-sided one."""
    from leoc.experiments.report import (
        PROVED_REGION_CHECK,
        RESPONSE_CHECK,
        ROA_CHECK,
        SWING_UP_CHECK,
    )
    from leoc.experiments.report.responses import BASELINE_OFFSET_CHECK
    from leoc.experiments.report.robustness import ROBUSTNESS_DEFICIT_CHECK

    return {
        "responses": RESPONSE_CHECK,
        "baseline_offsets": BASELINE_OFFSET_CHECK,
        "roa": ROA_CHECK,
        "proved_regions": PROVED_REGION_CHECK,
        "swing_up": SWING_UP_CHECK,
        "robustness": ROBUSTNESS_DEFICIT_CHECK,
    }


def load_results(folder: str | Path) -> dict[str, Any]:
    """The tables of a published study's ``results.json``, by the report's table names.

    Raises
    ------
    FileNotFoundError
        The folder has no ``results.json`` (not a published or reported study).
    """
    from leoc.experiments.report.build import RESULTS_ENTRIES

    path = Path(folder) / "results.json"
    if not path.is_file():
        raise FileNotFoundError(
            f"study: expected a reproduce folder with a report (results.json), found none in "
            f"{str(folder)!r}; run 'leoc plot {folder}' first"
        )
    results = json.loads(path.read_text(encoding="utf-8"))
    tables = {name: results.get(entry, []) for entry, name in RESULTS_ENTRIES}
    return {**tables, "meta": results.get("meta", {})}


def _verdict(passed: int, checked: int) -> str:
    """**holds** when every case checked passes, **fails** when none does, else **partly**."""
    if passed == checked:
        return "**holds**"
    return "**fails**" if passed == 0 else "**partly**"


def _improvement_cell(rows: Sequence[Mapping[str, Any]]) -> str:
    """Claim (ii): a pair passes unless it is resolved below 0.5 (the hybrid holds later)."""
    pairs = [r for r in rows if r["quantity"] == IMPROVEMENT and not is_missing(r["probability"])]
    if not pairs:
        return "*not measured*"
    above = sum(r["ci_low"] > EVEN for r in pairs)
    below = sum(r["ci_high"] < EVEN for r in pairs)
    return (
        f"{_verdict(len(pairs) - below, len(pairs))}: resolved above 0.5 in {above} of "
        f"{len(pairs)} hybrid-baseline pairs, below in {below}"
    )


def claim_cell(claim: HeadlineClaim, tables: Mapping[str, Any]) -> str:
    """The cell of ``claim`` for one study's ``tables`` (:func:`load_results`): verdict, the
    passing cases out of those checked, and the biggest miss."""
    wanted = _wanted(claim.kind)
    controllers = {row["controller"] for row in tables["swing_up"]}
    learned = {c for c in controllers if parse_controller(c).learner != LINEAR}
    if not any(wanted(controller) for controller in learned):
        return "*no such controller in this study*"
    if claim.check == "improvements":
        return _improvement_cell([r for r in tables["improvements"] if wanted(r["hybrid"])])
    check = _checks()[claim.check]
    rows = [row for row in tables[check.key] if wanted(row["controller"])]
    summary = check.summary(rows)
    if summary.checked == 0:
        return "*not measured*"
    passed = summary.checked - len(summary.failures)
    cell = f"{_verdict(passed, summary.checked)}: {passed} of {summary.checked} {summary.cases}"
    misses = [f"{f.subject} {f.shown}" for f in summary.failures[:SHOWN_MISS]]
    return cell + (f"; biggest miss: {misses[0]}" if misses else "")


VARIANT_HEADINGS = {"leoc": "leoc's defaults", "authors": "the authors' variant"}
"""Each implementation variant's column heading (another variant is named as it is)."""


def study_heading(folder: str | Path, tables: Mapping[str, Any]) -> str:
    """A study's column heading: its implementation variant and its folder as given."""
    variant = tables["meta"].get("variant", "leoc")
    return f"{VARIANT_HEADINGS.get(variant, f'variant {variant}')} (`{Path(folder).as_posix()}`)"


def headline_lines(studies: Sequence[str | Path]) -> list[str]:
    """The markdown table: one row per claim of :data:`CLAIMS`, one column per published study
    folder of ``studies`` (headed by :func:`study_heading`)."""
    loaded = [(folder, load_results(folder)) for folder in studies]
    tables = {study_heading(folder, t): t for folder, t in loaded}
    header = ["claim (the report's check)", *tables]
    rows = [[claim.claim, *(claim_cell(claim, t) for t in tables.values())] for claim in CLAIMS]
    return markdown_table(header, rows)


def proved_region_lines(studies: Sequence[str | Path]) -> list[str]:
    """The trained controllers' proved regions of several published studies in one table (the
    report's own rows and cells, a first column naming the study's folder); the studies that
    ran no proof add no row."""
    from leoc.experiments.report.proved_regions import proved_region_table

    return _stacked(proved_region_table, "proved_regions", studies)


def robustness_lines(studies: Sequence[str | Path]) -> list[str]:
    """The robustness protocol's scores of several published studies in one table (the
    report's own rows and cells, two first columns naming the study's folder and the system);
    the studies that ran no protocol add no row."""
    from leoc.experiments.report.robustness_protocol import protocol_table

    return _stacked(protocol_table, "robustness_protocol", studies)


def robustness_verdict_lines(studies: Sequence[str | Path]) -> list[str]:
    """Per category, whether each hybrid of several published studies is at least as robust
    as its LQR and more robust than its baseline, one row per study, system and hybrid
    (``leoc.experiments.report.robustness_protocol.verdict_summary_table``)."""
    from leoc.experiments.report.robustness_protocol import verdict_summary_table

    return _stacked(verdict_summary_table, "robustness_protocol_verdicts", studies)


def _stacked(table: Any, name: str, studies: Sequence[str | Path]) -> list[str]:
    """The report table ``name`` of every study, rendered by ``table`` with the study's folder
    in front (:func:`~leoc.experiments.markdown.stacked_tables`)."""
    groups = {Path(folder).as_posix(): load_results(folder)[name] for folder in studies}
    return stacked_tables(table, groups)


CROSS_STUDY_TABLES: dict[str, tuple[Callable[[Sequence[str | Path]], list[str]], str, str]] = {
    "proved_regions": (proved_region_lines, PROVED_BEGIN, PROVED_END),
    "robustness": (robustness_lines, ROBUSTNESS_BEGIN, ROBUSTNESS_END),
    "robustness_verdicts": (robustness_verdict_lines, VERDICTS_BEGIN, VERDICTS_END),
}
"""The tables across several studies by name (``leoc headline``'s flag, ``-`` for ``_``):
the function writing its lines from the study folders, and its begin and end markers."""


def write_headline(
    path: str | Path, lines: Sequence[str], begin: str = BEGIN, end: str = END
) -> bool:
    """Put ``lines`` between the ``begin`` and ``end`` lines (default :data:`BEGIN` and
    :data:`END`) of the markdown file ``path`` (atomically); whether the file changed.

    Raises
    ------
    ValueError
        The file lacks either marker, or has them out of order (nothing is written).
    """
    from leoc.io import write_text_atomic

    target = Path(path)
    text = target.read_text(encoding="utf-8")
    lines_in = text.split("\n")
    if begin not in lines_in or end not in lines_in:
        found = "neither" if begin not in lines_in and end not in lines_in else "one of them"
        raise ValueError(
            f"--write: expected the lines {begin!r} and {end!r} in {str(target)!r}, found {found}"
        )
    start, stop = lines_in.index(begin), lines_in.index(end)
    if stop < start:
        raise ValueError(f"--write: expected {begin!r} before {end!r} in {str(target)!r}")
    new = "\n".join([*lines_in[: start + 1], *lines, *lines_in[stop:]])
    if new == text:
        return False
    write_text_atomic(target, new)
    return True
