"""Appendix D side by side: the paper, leoc with the authors' variant, and leoc's defaults.

Every run of ``leoc reproduce`` measures its impulse response with the authors' metric set too
(``metrics_authors``, :mod:`leoc.evaluation.metric_sets`), so the rows of the paper's appendix D
can be compared like with like. A reproduce folder holds runs of one variant; its report names a
*companion* folder of the other variant (``leoc plot DIR --compare OTHER``, recorded in
``meta.json`` as a path relative to ``DIR``), and the table then carries both.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from leoc.evaluation.metrics import (
    MetricsSummary,
    ResponseMetrics,
    authors_response_metrics,
    summarise_metrics,
)
from leoc.experiments.layout import META_FILE, Evaluations, load_evaluations
from leoc.experiments.markdown import markdown_table
from leoc.experiments.paper import PAPER_IMPULSE_METRICS, PaperMetrics

__all__ = [
    "AppendixRow",
    "appendix_d_rows",
    "appendix_d_table",
    "appendix_d_verdict_lines",
    "appendix_d_verdicts",
    "authors_metrics_from_trace",
    "companion_evaluations",
    "metric_verdict",
    "row_verdict",
]

# The controllers of appendix D, in its order; "linear" is the paper's single linear row (the
# LQR at dt).
APPENDIX_CONTROLLERS = ("linear", "ddpg_baseline", "ddpg_hybrid", "pilco_baseline", "pilco_hybrid")
VARIANT_ORDER = ("authors", "leoc")
VARIANT_HEADERS = {"authors": "leoc, authors' variant", "leoc": "leoc default"}
METRIC_HEADERS = (
    ("steady_state_error", "steady-state error"),
    ("overshoot", "overshoot"),
    ("settling_time", "settling time [steps]"),
)
FMT = "{:.3g}"


class AppendixRow(NamedTuple):
    """One row of appendix D: the paper's numbers and each variant's authors' metrics."""

    system: str
    controller: str
    paper: PaperMetrics
    measured: dict[str, MetricsSummary | None]  # variant name -> summary over seeds
    # variant name -> whether it ran the controller (its runs may predate the authors' metrics)
    ran: dict[str, bool] | None = None

    def missing(self, variant: str) -> str:
        """Why a variant has no summary: "not run", or "not measured" for runs evaluated
        before leoc measured the authors' metrics."""
        return "not measured" if (self.ran or {}).get(variant) else "not run"


def companion_evaluations(out_dir: Path, meta: dict[str, Any]) -> tuple[str, Evaluations] | None:
    """The variant and evaluations of the companion folder named in ``meta['compare']``, or
    None when there is none.

    Raises
    ------
    FileNotFoundError
        The recorded companion folder does not exist (anymore).
    """
    relative = meta.get("compare")
    if not relative:
        return None
    other = (out_dir / relative).resolve()
    meta_path = other / META_FILE
    if not meta_path.is_file():
        raise FileNotFoundError(
            f"compare: the companion folder {str(other)!r} recorded in {out_dir / META_FILE} "
            "has no meta.json; run 'leoc plot' with --compare on an existing reproduce folder"
        )
    other_meta = json.loads(meta_path.read_text())
    return other_meta.get("variant", "leoc"), load_evaluations(other, other_meta)


def authors_metrics_from_trace(system: str, impulse: Mapping[str, Any]) -> ResponseMetrics:
    """The authors' impulse metrics measured from a run's stored leoc trace.

    For runs evaluated before leoc recorded the authors' metrics (``metrics_authors``): the
    stored deviation e (``deviation``, leoc's wrapped deviation of the main coordinate) is
    mapped to the authors' arcsin(sin e) in degrees for an angle (as is for a position), then
    measured by :func:`leoc.evaluation.metrics.authors_response_metrics` over the stored record.

    Parameters
    ----------
    system
        The system's name (:func:`leoc.systems.make_system`).
    impulse
        A run's ``responses["impulse"]`` entry of its ``evaluation.json``: ``deviation`` (T
        samples) and ``metrics`` (leoc's, whose ``terminated`` is kept).

    Returns
    -------
    ResponseMetrics
        The authors' metrics; equal to ``metrics_authors`` where a run recorded them over a
        record of the same length.
    """
    from leoc.systems import make_system  # torch: not needed to import this module

    e = np.asarray(impulse["deviation"], dtype=float)
    if make_system(system).main_in_degrees:
        e = np.degrees(np.arcsin(np.sin(np.radians(e))))
    terminated = bool(impulse["metrics"].get("terminated", False))
    return authors_response_metrics(e, terminated=terminated)


def _authors_metrics(
    system: str, impulse: Mapping[str, Any], from_traces: bool
) -> ResponseMetrics | None:
    """A run's recorded authors' metrics; else measured from its trace, or None."""
    if impulse.get("metrics_authors") is not None:
        return ResponseMetrics(**impulse["metrics_authors"])
    return authors_metrics_from_trace(system, impulse) if from_traces else None


def _authors_summary(
    system: str, runs: list[dict[str, Any]] | None, from_traces: bool = False
) -> MetricsSummary | None:
    if not runs:
        return None
    entries = [_authors_metrics(system, run["responses"]["impulse"], from_traces) for run in runs]
    measured = [entry for entry in entries if entry is not None]
    if len(measured) < len(entries):
        return None  # runs evaluated before leoc measured the authors' metrics
    return summarise_metrics(measured)


def appendix_d_rows(
    by_variant: dict[str, Evaluations], from_traces: bool = False
) -> list[AppendixRow]:
    """Rows of appendix D (the paper's order) with each variant's authors' impulse metrics
    (mean and std over seeds) where that variant ran the controller; ``from_traces``: runs
    that did not record them are measured from their stored traces
    (:func:`authors_metrics_from_trace`), else the row says they were not measured."""
    rows = []
    for system, papers in PAPER_IMPULSE_METRICS.items():
        for controller in APPENDIX_CONTROLLERS:
            runs = {
                name: evaluations.get(system, {}).get(controller)
                for name, evaluations in by_variant.items()
            }
            measured = {
                name: _authors_summary(system, found, from_traces) for name, found in runs.items()
            }
            ran = {name: bool(found) for name, found in runs.items()}
            rows.append(AppendixRow(system, controller, papers[controller], measured, ran))
    return rows


def _paper_cell(value: tuple[float, float] | None) -> str:
    if value is None:
        return "-"
    mean, std = value
    return f"{FMT.format(mean)} ± {FMT.format(abs(std))}"


def _measured_cell(summary: MetricsSummary | None, metric: str, missing: str) -> str:
    if summary is None:
        return missing
    if metric == "settling_time":
        if summary.n_settled == 0:
            return f"not settled (0/{summary.n_runs})"
        cell = f"{summary.settling_time_mean:.1f} ± {summary.settling_time_std:.2g}"
        settled = f" ({summary.n_settled}/{summary.n_runs})"
        return cell + ("" if summary.n_settled == summary.n_runs else settled)
    mean = getattr(summary, f"{metric}_mean")
    std = getattr(summary, f"{metric}_std")
    return f"{FMT.format(mean)} ± {FMT.format(std)}"


def appendix_d_table(rows: list[AppendixRow]) -> list[str]:
    """Markdown: per row of appendix D and per metric, the paper and each variant present."""
    variants = [name for name in VARIANT_ORDER if rows and name in rows[0].measured]
    headers = ["system", "controller"]
    for _, label in METRIC_HEADERS:
        headers += [f"{label}: paper"] + [f"{label}: {VARIANT_HEADERS[v]}" for v in variants]
    table = []
    for row in rows:
        cells = [row.system, row.controller]
        for metric, _ in METRIC_HEADERS:
            cells.append(_paper_cell(getattr(row.paper, metric)))
            cells += [_measured_cell(row.measured[v], metric, row.missing(v)) for v in variants]
        table.append(cells)
    return markdown_table(headers, table)


# ------------------------------------------------------------------------------------ verdicts
SCALE_SHARE = 0.02
"""Share of a metric's scale added to the verdict's tolerance (round-off, printed digits)."""

#: How a metric compares with the paper's number (:func:`metric_verdict`).
AGREES, DIFFERS, SPREAD, UNSETTLED, NOT_RUN = (
    "agrees",
    "differs",
    "seeds disagree",
    "not settled in every run",
    "not run",
)


def metric_scale(paper: PaperMetrics, metric: str) -> float:
    """The size against which a metric's difference is judged: the paper's overshoot for the
    steady-state error (errors of order 1e-13 are round-off against a response of size 0.45),
    the paper's own value otherwise (0 when the paper prints none)."""
    if metric == "steady_state_error":
        return abs((paper.overshoot or paper.steady_state_error)[0])
    value = getattr(paper, metric)
    return abs(value[0]) if value else 0.0


def metric_verdict(paper: PaperMetrics, metric: str, summary: MetricsSummary | None) -> str:
    """Whether a variant's mean over its n runs reproduces the paper's number for ``metric``.

    The tolerance is two standard errors of the difference of the means,
    2 sqrt((std^2 + paper std^2) / n), plus :data:`SCALE_SHARE` of :func:`metric_scale`:
    DIFFERS beyond it; within it, SPREAD when the two standard errors alone exceed the scale
    (the seeds disagree so much that n of them cannot tell; not a reproduction), else AGREES. A
    settling time reproduces only when every run settled (the paper's means are over settled
    runs of all its seeds): UNSETTLED otherwise. A metric the paper does not print agrees.
    """
    printed = getattr(paper, metric)
    if printed is None:
        return AGREES
    if summary is None:
        return NOT_RUN
    if metric == "settling_time" and summary.n_settled < summary.n_runs:
        return UNSETTLED
    mean = getattr(summary, f"{metric}_mean")
    std = getattr(summary, f"{metric}_std")
    paper_mean, paper_std = printed
    scale = metric_scale(paper, metric)
    errors = 2.0 * math.sqrt((paper_std**2 + std**2) / max(summary.n_runs, 1))
    if abs(mean - paper_mean) > errors + SCALE_SHARE * scale:
        return DIFFERS
    return SPREAD if errors > scale else AGREES


def row_verdict(row: AppendixRow, variant: str) -> dict[str, str] | None:
    """The metrics of ``row`` that ``variant`` does not reproduce, each with its verdict ({}:
    the row reproduces), or None when the variant has no summary (:meth:`AppendixRow.missing`
    says why)."""
    summary = row.measured.get(variant)
    if summary is None:
        return None
    verdicts = {metric: metric_verdict(row.paper, metric, summary) for metric, _ in METRIC_HEADERS}
    return {metric: word for metric, word in verdicts.items() if word != AGREES}


VERDICT_LABELS = {
    "steady_state_error": "steady-state error",
    "overshoot": "overshoot",
    "settling_time": "settling time",
}


def _verdict_cell(row: AppendixRow, variant: str, missed: dict[str, str] | None) -> str:
    """A row's verdict for one variant: why it has none, reproduces, or what does not."""
    if missed is None:
        return row.missing(variant)
    if not missed:
        return "**reproduces**"
    return "no: " + "; ".join(f"{VERDICT_LABELS[m]} {word}" for m, word in missed.items())


def _count_line(variant: str, judged: list[tuple[AppendixRow, dict[str, str] | None]]) -> str:
    """How many of the rows a variant measured reproduce (named), and how many it lacks."""
    ran = [(row, missed) for row, missed in judged if missed is not None]
    good = [f"{row.system} {row.controller}" for row, missed in ran if not missed]
    return (
        f"- {VARIANT_HEADERS[variant]}: {len(good)} of {len(ran)} rows measured reproduce"
        + (f" ({', '.join(good)})" if good else "")
        + "".join(
            f"; {count} {word}"
            for word in ("not run", "not measured")
            if (count := sum(row.missing(variant) == word for row, m in judged if m is None))
        )
        + "."
    )


def appendix_d_verdict_lines(rows: list[AppendixRow]) -> list[str]:
    """Markdown: per row of appendix D and variant, whether it reproduces the paper's row (its
    three metrics within :func:`metric_verdict`'s tolerance), then the count per variant."""
    variants = [name for name in VARIANT_ORDER if rows and name in rows[0].measured]
    verdicts = {v: [row_verdict(row, v) for row in rows] for v in variants}
    table = [
        [row.system, row.controller] + [_verdict_cell(row, v, verdicts[v][index]) for v in variants]
        for index, row in enumerate(rows)
    ]
    headers = ["system", "controller", *(VARIANT_HEADERS[v] for v in variants)]
    counts = [_count_line(v, list(zip(rows, verdicts[v], strict=True))) for v in variants]
    return [*markdown_table(headers, table), "", *counts]


def _traced_runs(variant: str, evaluations: Evaluations) -> list[str]:
    """``variant system controller (N-step records)`` of each appendix-D controller whose runs
    lack the authors' metrics (measured from their traces)."""
    found = []
    for system, by_controller in evaluations.items():
        for controller in APPENDIX_CONTROLLERS:
            impulses = [run["responses"]["impulse"] for run in by_controller.get(controller, [])]
            lengths = sorted(
                {len(i["deviation"]) for i in impulses if i.get("metrics_authors") is None}
            )
            if lengths:
                steps = "/".join(map(str, lengths))
                found.append(f"{VARIANT_HEADERS[variant]}: {system} {controller} ({steps}-step)")
    return found


def appendix_d_verdicts(folders: Sequence[str | Path]) -> list[str]:
    """Appendix D row by row from reproduce (or published) folders, one per variant.

    Like the report's appendix-D section, but every run counts: runs evaluated before leoc
    recorded the authors' metrics are measured from their stored impulse traces
    (:func:`authors_metrics_from_trace`) instead of being *not measured*.

    Parameters
    ----------
    folders
        Reproduce folders, each of another variant (``meta.json``'s ``variant``), e.g.
        ``results/paper-authors`` and ``results/paper``.

    Returns
    -------
    list[str]
        Markdown lines: the table of :func:`appendix_d_table` (the paper and each variant's
        mean ± std per metric), the verdicts of :func:`appendix_d_verdict_lines`, then one
        line per controller measured from traces, with its record length.

    Raises
    ------
    FileNotFoundError
        A folder has no ``meta.json``.
    ValueError
        Two folders hold the same variant.
    """
    by_variant: dict[str, Evaluations] = {}
    for folder in map(Path, folders):
        if not (folder / META_FILE).is_file():
            raise FileNotFoundError(f"folders: no {META_FILE} in {str(folder)!r}")
        meta = json.loads((folder / META_FILE).read_text())
        variant = meta.get("variant", "leoc")
        if variant in by_variant:
            raise ValueError(f"folders: expected one folder per variant, found {variant!r} twice")
        by_variant[variant] = load_evaluations(folder, meta)
    rows = appendix_d_rows(by_variant, from_traces=True)
    traced = [line for v, e in by_variant.items() for line in _traced_runs(v, e)]
    notes = [f"- measured from the stored traces: {line}" for line in traced]
    return [*appendix_d_table(rows), "", *appendix_d_verdict_lines(rows), *notes]


def appendix_d_section(out_dir: Path, meta: dict[str, Any], evaluations: Evaluations) -> list[str]:
    """The report section: definitions, the table, and which folders its columns come from."""
    by_variant = {meta.get("variant", "leoc"): evaluations}
    companion = companion_evaluations(out_dir, meta)
    source = f"this folder ({meta.get('variant', 'leoc')} variant)"
    if companion is not None:
        name, other = companion
        by_variant.setdefault(name, other)
        source += f" and `{meta['compare']}` ({name} variant)"
    lines = [
        "## Appendix D side by side (the authors' metric set)",
        "",
        "Impulse response, measured with the authors' definitions (nrjc/LEOC "
        "`plotting/plotter.py`) so that it compares with the paper's numbers: e = arcsin(sin "
        "theta) in degrees (the mountain car's position in metres); steady-state error = the "
        "last sample; 'overshoot' = the peak deviation from it; settling time = the first step "
        "after which e stays within +/- pi/180 of it (the record length when it never leaves "
        "that band: the paper's mountain-car 201). Mean ± std over seeds; settling over the "
        f"runs that reached a steady state (their count in brackets when not all). Columns from "
        f"{source}.",
        "",
    ]
    rows = appendix_d_rows(by_variant)
    verdict = [
        "",
        "**Row by row.** A row reproduces when each of its three metrics is within two standard "
        "errors of the difference of the means, 2 sqrt((std^2 + paper std^2) / n) over the n "
        f"seeds of the run, plus {SCALE_SHARE:.0%} of the metric's scale (the paper's overshoot "
        "for the steady-state error, the paper's value otherwise). *Seeds disagree*: the two "
        "standard errors alone exceed the scale, so n seeds cannot tell (not a reproduction); a "
        "settling time must be reached in every run; a metric the paper does not print agrees; "
        "a difference beyond the tolerance *differs* however much the seeds disagree. *Not "
        "measured*: runs evaluated before leoc recorded the authors' metrics "
        "(`leoc.experiments.appendix_d.appendix_d_verdicts` measures them from the stored "
        "traces).",
        "",
    ]
    return lines + appendix_d_table(rows) + verdict + appendix_d_verdict_lines(rows) + [""]
