"""The report of ``leoc reproduce``, built only from the saved numbers (``leoc plot`` reruns it).

Outputs in the reproduce folder: ``results.json`` (every aggregated number), ``responses.csv``,
``robustness.csv``, ``learning_curves.csv``, ``learning_curves.png`` (paper figure 6),
``responses.png`` (figure 7), ``robustness.png`` (figure 8), ``relevance.png`` (figure 4) and
``report.md``.

Each section of ``report.md`` is a module of this package (``header``, ``overview``,
``definitions``, ``appendix``, ``responses``, ``robustness``, ``robustness_protocol``,
``swing_up``, ``roa``, ``proved_regions``, ``claims``, ``seeds``, ``figures``) with the
interface of ``leoc.experiments.report.base.Section``: what it computes from the runs, what it
checks, what it renders. ``build`` assembles them in
the order of its ``SECTIONS``. This package re-exports the names other code uses.
"""

from leoc.experiments.report.base import Check, Report, Section, Study
from leoc.experiments.report.build import (
    SECTIONS,
    load_study,
    record_companion,
    render_markdown,
    write_report,
)
from leoc.experiments.report.figures import curve_summary, relevance_traces, write_relevance_figure
from leoc.experiments.report.header import (
    code_line,
    code_versions,
    invocations_lines,
    machine_line,
    model_selection_text,
    recorded_selection,
)
from leoc.experiments.report.proved_regions import (
    PROVED_REGION_CHECK,
    proved_region_summary,
    proved_region_table,
)
from leoc.experiments.report.responses import (
    RESPONSE_CHECK,
    paper_cells,
    response_summary,
    response_table,
)
from leoc.experiments.report.roa import ROA_CHECK, roa_summary, roa_table
from leoc.experiments.report.robustness import (
    ROBUSTNESS_CHECK,
    robustness_summary,
    robustness_table,
)
from leoc.experiments.report.robustness_protocol import protocol_summary, protocol_table
from leoc.experiments.report.seeds import (
    first_hold_seconds,
    improvement_rows,
    improvement_table,
    seed_statistics,
    seed_table,
)
from leoc.experiments.report.swing_up import (
    SWING_UP_CHECK,
    swing_up_summary,
    swing_up_table,
)

__all__ = [
    "PROVED_REGION_CHECK",
    "RESPONSE_CHECK",
    "ROA_CHECK",
    "ROBUSTNESS_CHECK",
    "SECTIONS",
    "SWING_UP_CHECK",
    "Check",
    "Report",
    "Section",
    "Study",
    "code_line",
    "code_versions",
    "curve_summary",
    "first_hold_seconds",
    "improvement_rows",
    "improvement_table",
    "invocations_lines",
    "load_study",
    "machine_line",
    "model_selection_text",
    "paper_cells",
    "protocol_summary",
    "protocol_table",
    "proved_region_summary",
    "proved_region_table",
    "record_companion",
    "recorded_selection",
    "relevance_traces",
    "render_markdown",
    "response_summary",
    "response_table",
    "roa_summary",
    "roa_table",
    "robustness_summary",
    "robustness_table",
    "seed_statistics",
    "seed_table",
    "swing_up_summary",
    "swing_up_table",
    "write_relevance_figure",
    "write_report",
]
