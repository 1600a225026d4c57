"""The report's ``## Summary``: what worked and what failed, from every section's check
(:func:`leoc.experiments.summary.summary_markdown`)."""

from __future__ import annotations

from leoc.experiments.report.base import Report, Section, missing_runs
from leoc.experiments.summary import summary_markdown


def render(report: Report) -> list[str]:
    """Per check, the cases that worked and the biggest failures; the runs without results."""
    study = report.study
    return summary_markdown(report.checks, missing_runs(study.meta, study.evaluations))


SECTION = Section(render)
