"""The report's hybrids against their LQR where the comparison can fail
(:func:`leoc.experiments.claims_report.hybrid_claims_section`)."""

from __future__ import annotations

from leoc.experiments.claims_report import hybrid_claims_section
from leoc.experiments.report.base import Report, Section


def render(report: Report) -> list[str]:
    """The section's lines (none when no run has ``hybrid_claims``)."""
    return hybrid_claims_section(report.study.evaluations)


SECTION = Section(render)
