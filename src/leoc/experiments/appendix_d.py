"""Appendix D side by side: the paper, leoc with the authors' variant, and leoc's defaults.

Every run of ``leoc reproduce`` measures its impulse response with the authors' metric set too
(``metrics_authors``, :mod:`leoc.evaluation.metric_sets`), so the rows of the paper's appendix D
can be compared like with like. A reproduce folder holds runs of one variant; its report names a
*companion* folder of the other variant (``leoc plot DIR --compare OTHER``, recorded in
``meta.json`` as a path relative to ``DIR``), and the table then carries both.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, NamedTuple

from leoc.evaluation.metrics import MetricsSummary, ResponseMetrics, summarise_metrics
from leoc.experiments.layout import META_FILE, Evaluations, load_evaluations
from leoc.experiments.paper import PAPER_IMPULSE_METRICS, PaperMetrics

__all__ = [
    "AppendixRow",
    "appendix_d_rows",
    "appendix_d_table",
    "companion_evaluations",
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


def _authors_summary(runs: list[dict[str, Any]] | None) -> MetricsSummary | None:
    if not runs:
        return None
    entries = [run["responses"]["impulse"].get("metrics_authors") for run in runs]
    if any(entry is None for entry in entries):
        return None  # runs evaluated before leoc measured the authors' metrics
    return summarise_metrics([ResponseMetrics(**entry) for entry in entries])


def appendix_d_rows(by_variant: dict[str, Evaluations]) -> list[AppendixRow]:
    """Rows of appendix D (the paper's order) with each variant's authors' impulse metrics
    (mean and std over seeds) where that variant ran the controller."""
    rows = []
    for system, papers in PAPER_IMPULSE_METRICS.items():
        for controller in APPENDIX_CONTROLLERS:
            measured = {
                name: _authors_summary(evaluations.get(system, {}).get(controller))
                for name, evaluations in by_variant.items()
            }
            rows.append(AppendixRow(system, controller, papers[controller], measured))
    return rows


def _paper_cell(value: tuple[float, float] | None) -> str:
    if value is None:
        return "-"
    mean, std = value
    return f"{FMT.format(mean)} ± {FMT.format(abs(std))}"


def _measured_cell(summary: MetricsSummary | None, metric: str) -> str:
    if summary is None:
        return "not run"
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
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    for row in rows:
        cells = [row.system, row.controller]
        for metric, _ in METRIC_HEADERS:
            cells.append(_paper_cell(getattr(row.paper, metric)))
            cells += [_measured_cell(row.measured[v], metric) for v in variants]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


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
    return lines + appendix_d_table(appendix_d_rows(by_variant)) + [""]
