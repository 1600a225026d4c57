"""What every section of the report shares: its interface, its inputs and the cell formats.

A section (:class:`Section`) is a module of this package with a ``SECTION`` entry in
:data:`leoc.experiments.report.build.SECTIONS`:

- ``compute(study)``: the section's tables from the study's runs (``results.json`` entries),
  by name; optional;
- ``check``: a :class:`Check` of one of those tables, whose failures are the section's flags
  and its line of the report's summary; optional;
- ``render(report)``: the section's markdown lines.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NamedTuple

from leoc.experiments.layout import Evaluations
from leoc.experiments.profiles import CONTROLLER_LABELS, CONTROLLERS
from leoc.experiments.summary import CheckSummary, Failure, check_summary
from leoc.names import parse_controller

FMT = "{:.3g}"

Rows = list[dict[str, Any]]


class Study(NamedTuple):
    """A reproduce folder as the sections read it: the folder, its ``meta.json``, its runs."""

    out: Path
    meta: dict[str, Any]
    evaluations: Evaluations


class Report(NamedTuple):
    """What a section renders from: the study, every section's tables (by name), the flags and
    checks (by check key, :meth:`CheckSummary.to_json`), the figures written (title, file) and
    the summed wall time of the runs [s]."""

    study: Study
    tables: dict[str, Any]
    flags: dict[str, list[str]]
    checks: dict[str, dict[str, Any]]
    figures: list[tuple[str, str]]
    run_seconds: float


class Check(NamedTuple):
    """A section's check of its table ``key``: ``failures(rows)`` gives the cases checked and
    the failures in the rows' order; ``cases``, ``threshold`` and ``worked`` are the words of
    the report's summary (:func:`leoc.experiments.summary.check_summary`)."""

    key: str
    failures: Callable[[Rows], tuple[int, list[Failure]]]
    cases: str
    threshold: str
    worked: str

    def summary(self, rows: Rows) -> CheckSummary:
        """The check over ``rows``, failures biggest first."""
        return check_summary(
            *self.failures(rows), cases=self.cases, threshold=self.threshold, worked=self.worked
        )

    def flags(self, rows: Rows) -> list[str]:
        """The sentence of each failure, in the rows' order."""
        return [failure.flag for failure in self.failures(rows)[1]]


class Section(NamedTuple):
    """One part of ``report.md``: its markdown, and optionally the tables it computes and the
    check it makes (see the module's docstring)."""

    render: Callable[[Report], list[str]]
    compute: Callable[[Study], dict[str, Any]] | None = None
    check: Check | None = None


def ordered(controllers: dict[str, Any]) -> list[str]:
    """The controllers of ``controllers`` in the profiles' order."""
    return [name for name in CONTROLLERS if name in controllers]


def relevances(evaluations: Evaluations) -> set[str]:
    """The relevance designs of the study's hybrids (``paper``, ``roa``, ``lyapunov``)."""
    return {
        relevance
        for by_controller in evaluations.values()
        for controller in by_controller
        if (relevance := parse_controller(controller).relevance) is not None
    }


def label(controller: str) -> str:
    """A controller's name as the report prints it."""
    return CONTROLLER_LABELS.get(controller, controller)


def pm(mean: float, std: float) -> str:
    """``mean ± std``, or ``-`` for a NaN mean."""
    if math.isnan(mean):
        return "-"
    return f"{FMT.format(mean)} ± {FMT.format(std)}"


def number(value: float) -> str:
    """A number as the tables print it, ``-`` for NaN."""
    return "-" if math.isnan(value) else FMT.format(value)


def interval(low: float | None, high: float | None, note: str | None) -> str:
    """``[low, high]``, or the note in brackets when there is no interval."""
    if low is None or high is None:
        return f"({note})" if note else ""
    return f"[{FMT.format(low)}, {FMT.format(high)}]"


def flag_block(flags: Sequence[str], none_text: str) -> list[str]:
    """A section's list of what failed, or its sentence that nothing did."""
    if not flags:
        return [f"**Checks: {none_text}**", ""]
    return ["**What failed:**", ""] + [f"- {flag}" for flag in flags] + [""]


def missing_runs(meta: dict[str, Any], evaluations: Evaluations) -> list[str]:
    """``system/controller`` of each run the study planned and has no results of."""
    return [
        f"{s}/{c}"
        for s in meta.get("systems", [])
        for c in meta.get("controllers", [])
        if c not in evaluations.get(s, {})
    ]
