"""The report's hybrids against their LQR where the comparison can fail
(:func:`leoc.experiments.claims_report.hybrid_claims_section`)."""

from __future__ import annotations

from leoc.experiments.claims_report import hybrid_claims_section
from leoc.experiments.report.base import Report, Section, relevances

PAPER_SENTENCE = "the paper's relevance has r < 1 everywhere but at a."
"""The opening's words on the relevance without a flat top, which the Lyapunov relevance
shares."""
WITH_LYAPUNOV = (
    "the paper's relevance and the Lyapunov relevance (r = (1 + V~/(lambda rho))^-2, no flat "
    "top) have r < 1 everywhere but at a."
)
""":data:`PAPER_SENTENCE` in a study with a Lyapunov-relevance hybrid."""
LYAPUNOV_NOTE = (
    "The Lyapunov-relevance hybrids have no flat top: r = (1 + V~/(lambda rho))^-2 < 1 "
    "everywhere but at a, as with the paper's relevance."
)
"""Its own paragraph after the heading, where the opening no longer has
:data:`PAPER_SENTENCE`."""


def render(report: Report) -> list[str]:
    """The section's lines (none when no run has ``hybrid_claims``); in a study with a
    Lyapunov-relevance hybrid, the opening says that it has no flat top (the opening names the
    ROA's flat top and the paper's relevance only). Which comparisons are by construction is
    the runs' own record (r = 1 along the test), whatever the relevance."""
    lines = hybrid_claims_section(report.study.evaluations)
    if not lines or "lyapunov" not in relevances(report.study.evaluations):
        return lines
    said = [line.replace(PAPER_SENTENCE, WITH_LYAPUNOV) for line in lines]
    if said != lines:
        return said
    heading = next(i for i, line in enumerate(lines) if line.startswith("## "))
    return [*lines[: heading + 1], "", LYAPUNOV_NOTE, *lines[heading + 1 :]]


SECTION = Section(render)
