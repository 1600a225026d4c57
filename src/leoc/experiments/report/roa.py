"""The report's region of attraction: each controller's LQR certificate at its period and its
empirical basin, and the check that every hybrid holds its LQR's whole certified set."""

from __future__ import annotations

from typing import Any

import numpy as np

from leoc.experiments.claims_report import roa_estimate_lines, roa_method_text
from leoc.experiments.layout import Evaluations
from leoc.experiments.markdown import markdown_table
from leoc.experiments.report.base import (
    FMT,
    Check,
    Report,
    Rows,
    Section,
    Study,
    flag_block,
    label,
    ordered,
)
from leoc.experiments.stats import percent
from leoc.experiments.summary import Failure
from leoc.names import parse_controller

ROA_HEADERS = (
    "system",
    "controller",
    "period",
    "certified rho (LQR at that period)",
    "extent per state",
    "certified share of the box",
    "basin: box held",
    "basin: certified set held",
)


def _row(system: str, controller: str, runs: list[dict[str, Any]]) -> dict[str, Any]:
    """One controller's certificate (its first run's) and basin shares (mean over seeds)."""
    first = runs[0]["roa"]
    inside = [run["roa"]["certified_set_held"] for run in runs]
    return {
        "system": system,
        "controller": controller,
        "action_repeat": runs[0].get("action_repeat", 1),
        "rho": first["certificate"]["rho"],
        "extent": first["certificate"]["extent"],
        "samples": first["certificate"]["samples"],
        "violation_bound": first["certificate"]["violation_bound"],
        "confidence": first["certificate"]["confidence"],
        # runs written before the fraction was stored alone hold [fraction, error]
        "certified_box_fraction": float(np.ravel(first["certified_box_fraction"])[0]),
        "basin_box_fraction": float(np.mean([run["roa"]["basin_box_fraction"] for run in runs])),
        "certified_set_held": None if None in inside else float(np.mean(inside)),
        "n_runs": len(runs),
    }


def roa_summary(evaluations: Evaluations) -> Rows:
    """Rows: system, controller, its period, the certified rho and extent of the LQR at that
    period, the certified set's share of the basin box, and the controller's empirical basin:
    share of the box held, share of the certified set held (mean over seeds)."""
    rows = []
    for system, by_controller in evaluations.items():
        for controller in ordered(by_controller):
            runs = [run for run in by_controller[controller] if run.get("roa")]
            if runs:
                rows.append(_row(system, controller, runs))
    return rows


def _roa_failures(rows: Rows) -> tuple[int, list[Failure]]:
    """The hybrids checked, and those whose empirical basin does not contain their LQR's
    certified set (size: the share of the set's starts not held), in the rows' order."""
    checked = [
        row
        for row in rows
        if parse_controller(row["controller"]).hybrid and row["certified_set_held"] is not None
    ]
    return len(checked), [
        Failure(
            f"{row['system']} {label(row['controller'])}",
            1.0 - row["certified_set_held"],
            f"holds {percent(row['certified_set_held'])}",
            "",
            f"**{row['system']} {label(row['controller'])}** holds only "
            f"{percent(row['certified_set_held'])} of the starts in its LQR's certified region "
            "of attraction.",
        )
        for row in checked
        if row["certified_set_held"] < 1.0
    ]


#: The check: every hybrid holds its LQR's whole certified set.
ROA_CHECK = Check(
    "roa",
    _roa_failures,
    cases="hybrids",
    threshold="every start of its LQR's certified set held",
    worked="hold their LQR's whole certified set",
)


def _roa_cells(row: dict[str, Any]) -> list[str]:
    extent = ", ".join(FMT.format(value) for value in row["extent"])
    inside = "-" if row["certified_set_held"] is None else percent(row["certified_set_held"])
    return [
        row["system"],
        label(row["controller"]),
        str(row["action_repeat"]),
        FMT.format(row["rho"]),
        f"± [{extent}]",
        percent(row["certified_box_fraction"]),
        percent(row["basin_box_fraction"]),
        inside,
    ]


def roa_table(rows: Rows) -> list[str]:
    """Markdown rows of the region-of-attraction table: certificate and empirical basins."""
    return markdown_table(ROA_HEADERS, [_roa_cells(row) for row in rows])


def compute(study: Study) -> dict[str, Any]:
    """The ``roa`` table (:func:`roa_summary`)."""
    return {"roa": roa_summary(study.evaluations)}


def render(report: Report) -> list[str]:
    """``## Region of attraction``: the method, the certificates' sampling, what failed, the
    table."""
    evaluations, rows = report.study.evaluations, report.tables["roa"]
    lines = [
        "",
        "## Region of attraction",
        "",
        roa_method_text(evaluations)
        + "controller's empirical basin: the share of seeded starts in the basin box, and of "
        "starts uniform in that certified set, that converge and hold. A hybrid whose basin "
        "contains the set holds 100% of the latter.",
        "",
    ]
    if rows:
        lines += roa_estimate_lines(evaluations, rows[0])
    lines += flag_block(report.flags["roa"], "every hybrid holds its LQR's whole certified set.")
    return lines + roa_table(rows)


SECTION = Section(render, compute, ROA_CHECK)
