"""What worked and what failed: the report's summary and the lines ``leoc reproduce`` prints.

Each check of the report (``leoc.experiments.report.write_report``) is stored in
``results.json``'s ``checks`` as a :class:`CheckSummary`: how many cases it checked, its
threshold and its failures, each with its size in the check's unit, biggest first. From them
the report's summary says in at most ``SUMMARY_MAX_LINES`` lines what worked and what failed,
naming the ``SHOWN_FAILURES`` biggest failures of each check (the sections list every one), and
the terminal gets one line per check after the wall time and before the paths to open.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

from leoc.experiments.layout import META_FILE

RESULTS_FILE = "results.json"
REPORT_FILE = "report.md"
FLAG_SECTIONS = {
    "responses": "impulse/step responses",
    "robustness": "robustness",
    "swing_up": "swing-up",
    "roa": "region of attraction",
    "proved_regions": "proved regions",
}
"""Report section of each group of checks (``results.json``'s ``flags`` and ``checks``)."""
SHOWN_FAILURES = 3
"""Failures named per check in the report's summary (the biggest)."""
SUMMARY_MAX_LINES = 17
"""Lines of the report's summary at most (its heading included): a worked and a failed line
per check of :data:`FLAG_SECTIONS`, the runs without results, headings and blank lines."""


class Failure(NamedTuple):
    """One failed case of a check.

    ``size`` is in the check's unit and larger is worse (it orders the failures); ``shown`` is
    the size as a reader reads it beside the check's threshold (``off by 33x``), ``detail`` the
    measurement behind it where ``shown`` does not say it (``peak deviation 108 vs 3.22``; may
    be empty), ``flag`` the sentence of the report's section."""

    subject: str
    size: float
    shown: str
    detail: str
    flag: str


class CheckSummary(NamedTuple):
    """One check over the cases of a report: ``cases`` names them (``"hybrid response
    tests"``), ``threshold`` is what a case must meet, ``worked`` what the passing cases do
    (``"match their LQR"``); ``failures`` biggest first."""

    checked: int
    cases: str
    threshold: str
    worked: str
    failures: list[Failure]

    def to_json(self) -> dict[str, Any]:
        """The ``results.json`` form (failures as mappings)."""
        return {**self._asdict(), "failures": [failure._asdict() for failure in self.failures]}


def check_summary(
    checked: int, failures: Sequence[Failure], *, cases: str, threshold: str, worked: str
) -> CheckSummary:
    """A :class:`CheckSummary` with its failures sorted biggest first (stable on ties)."""
    ranked = sorted(failures, key=lambda failure: failure.size, reverse=True)
    return CheckSummary(checked, cases, threshold, worked, ranked)


def _failed_text(key: str, check: Mapping[str, Any]) -> str:
    failures = check["failures"]
    named = "; ".join(
        f"{f['subject']} {f['shown']}" + (f" ({f['detail']})" if f["detail"] else "")
        for f in failures[:SHOWN_FAILURES]
    )
    more = len(failures) - SHOWN_FAILURES
    return (
        f"- **{FLAG_SECTIONS[key]}** (threshold: {check['threshold']}): {len(failures)} of "
        f"{check['checked']} {check['cases']}; biggest: {named}"
        + (f"; {more} more in its section." if more > 0 else ".")
    )


def summary_markdown(checks: Mapping[str, Mapping[str, Any]], missing: Sequence[str]) -> list[str]:
    """The report's ``## Summary`` (at most ``SUMMARY_MAX_LINES`` lines, the blank line that
    ends it included): per check, how many cases worked, and, for the checks that failed, the
    threshold, the count and the biggest failures with their sizes; then the runs without
    results. ``checks``: ``results.json``'s ``checks`` (:meth:`CheckSummary.to_json`)."""
    present = {key: checks[key] for key in FLAG_SECTIONS if checks.get(key, {}).get("checked")}
    worked = [
        f"- {FLAG_SECTIONS[key]}: {check['checked'] - len(check['failures'])} of "
        f"{check['checked']} {check['cases']} {check['worked']}."
        for key, check in present.items()
    ]
    failed = [_failed_text(key, check) for key, check in present.items() if check["failures"]]
    if missing:
        failed.append(f"- **runs without results** (failed or not run yet): {len(missing)}.")
    lines = ["## Summary", ""]
    lines += ["**What worked:**", *worked, ""] if worked else []
    if failed:
        lines += [
            "**What failed**, each failure's size against the check's threshold, the biggest "
            "first (the sections list every case):",
            *failed,
            "",
        ]
    else:
        lines += ["**What failed:** nothing; every check passed.", ""]
    return lines


def invocation_wall_seconds(meta: Mapping[str, Any]) -> list[float]:
    """The wall time [s] of each invocation of a reproduce folder (``meta.json``'s
    ``invocations``; a folder written before leoc logged them: its last invocation's, if
    any)."""
    invocations = meta.get("invocations") or []
    if invocations:
        return [float(item.get("wall_seconds", 0.0)) for item in invocations]
    last = meta.get("wall_seconds_last_invocation")
    return [] if last is None else [float(last)]


def wall_time_text(meta: Mapping[str, Any]) -> str | None:
    """``5710 s over 2 invocations (the last 11 s)`` or ``5699 s in one invocation`` (None:
    no invocation has recorded its time)."""
    walls = invocation_wall_seconds(meta)
    if not walls:
        return None
    if len(walls) == 1:
        return f"{walls[0]:.0f} s in one invocation"
    return f"{sum(walls):.0f} s over {len(walls)} invocations (the last {walls[-1]:.0f} s)"


def _check_row(key: str, check: Mapping[str, Any], width: int) -> str:
    failures = check["failures"]
    count = f"{len(failures)}/{check['checked']}"
    worst = f"worst: {failures[0]['subject']} {failures[0]['shown']}" if failures else "passed"
    return f"  {FLAG_SECTIONS[key]:<{width}}  {count:>7}  {worst}"


def summary_lines(out_dir: str | Path) -> list[str]:
    """The end-of-run summary of a reproduce folder whose report has been written: the pairs
    reported and the wall time of every invocation, the runs without results, one line per
    check (failed/checked and its worst failure), the paths to open."""
    out = Path(out_dir)
    results = json.loads((out / RESULTS_FILE).read_text())
    meta = json.loads((out / META_FILE).read_text())
    responses = results.get("responses", [])
    aggregated = {(row["system"], row["controller"]) for row in responses}
    missing = [
        f"{system}/{controller}"
        for system in meta.get("systems", [])
        for controller in meta.get("controllers", [])
        if (system, controller) not in aggregated
    ]
    wall = wall_time_text(meta)
    lines = [
        f"Finished: {len(aggregated)} system/controller pairs in the report"
        + (f"; wall time {wall}" if wall is not None else "")
        + "."
    ]
    if missing:
        lines.append(f"Without results (failed; see their train.log): {', '.join(missing)}.")
    checks = {k: c for k, c in results.get("checks", {}).items() if c.get("checked")}
    if not any(check["failures"] for check in checks.values()):
        lines.append("Checks: all passed." if checks else "Checks: none (no hybrid or learner).")
    else:
        lines.append("Checks failed/checked, the worst failure of each (report.md lists all):")
        width = max(len(FLAG_SECTIONS[key]) for key in checks)
        lines += [_check_row(key, checks[key], width) for key in FLAG_SECTIONS if key in checks]
    lines += [
        f"Report: {out / REPORT_FILE} (figures and CSV files beside it).",
        f"Redraw after a change: leoc plot {out}",
    ]
    return lines
