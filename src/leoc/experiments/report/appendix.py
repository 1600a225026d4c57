"""The report's appendix D side by side (:func:`leoc.experiments.appendix_d.appendix_d_section`;
it reads the companion folder, so it renders after the figures are written, as it always did)."""

from __future__ import annotations

from leoc.experiments.appendix_d import appendix_d_section
from leoc.experiments.report.base import Report, Section


def render(report: Report) -> list[str]:
    """The paper's appendix D beside this folder's (and its companion's) authors' metrics."""
    study = report.study
    return appendix_d_section(study.out, study.meta, study.evaluations)


SECTION = Section(render)
