"""The report's impulse and step responses: each controller's metrics over seeds, the paper's
appendix D beside the impulse table, and the check that every hybrid matches its LQR."""

from __future__ import annotations

import math
from typing import Any

from leoc.evaluation.metrics import ResponseMetrics, summarise_metrics
from leoc.evaluation.rollout import RESPONSE_TESTS
from leoc.experiments.layout import Evaluations
from leoc.experiments.markdown import markdown_table
from leoc.experiments.paper import PAPER_IMPULSE_METRICS
from leoc.experiments.profiles import LINEAR_CONTROLLERS, LINEAR_REFERENCE
from leoc.experiments.report.base import (
    FMT,
    Check,
    Report,
    Rows,
    Section,
    Study,
    flag_block,
    label,
    number,
    ordered,
    pm,
)
from leoc.experiments.summary import Failure
from leoc.names import controller_framework
from leoc.systems import make_system

# A hybrid "differs from its linear reference" when a metric differs by more than this fraction
# of the reference's value, with the reference floored at this fraction of its peak deviation
# (so 1e-12 vs 1e-13 of round-off in a zero steady-state error is not a difference).
RELATIVE_TOLERANCE = 0.01
ZERO_FLOOR_OF_PEAK = 0.01
COMPARED_METRICS = ("steady_state_error", "overshoot", "peak_deviation", "settling_time")
MULTIPLE_FROM = 10.0
"""A failure's size is shown as a multiple (``32x``) from this ratio on, as a percentage below."""
NEGATIVE_STD_MARK = "*"
NEGATIVE_STD_NOTE = (
    f"{NEGATIVE_STD_MARK} The paper prints this standard deviation with a minus sign; shown as "
    "its magnitude."
)
PAPER_COLUMNS = 3
RESPONSE_COLUMNS = (
    "system",
    "controller",
    "period [steps]",
    "steady-state error",
    "overshoot",
    "peak deviation",
    "settling time [steps]",
    "settling time [s]",
    "settled",
    "terminated",
)
PAPER_HEADERS = ("paper: steady-state error", "paper: overshoot", "paper: settling time")


def response_summary(evaluations: Evaluations) -> Rows:
    """Rows: system, test, controller, mean/std of the metrics over seeds, settled and
    terminated counts, settling time in seconds."""
    rows = []
    for system, by_controller in evaluations.items():
        dt = make_system(system).dt
        for test in RESPONSE_TESTS:
            for controller in ordered(by_controller):
                runs = by_controller[controller]
                summary = summarise_metrics(
                    [ResponseMetrics(**run["responses"][test]["metrics"]) for run in runs]
                )
                rows.append(
                    {
                        "system": system,
                        "test": test,
                        "controller": controller,
                        "action_repeat": runs[0].get("action_repeat", 1),
                        **summary._asdict(),
                        "settling_seconds_mean": summary.settling_time_mean * dt,
                    }
                )
    return rows


def _relative_difference(value: float, reference: float, peak: float) -> float:
    """|value - reference| as a fraction of the reference (floored at ``ZERO_FLOOR_OF_PEAK``
    of its peak deviation); NaN when only one of them is NaN (one run settles, the other not),
    0 when both are."""
    if math.isnan(value) or math.isnan(reference):
        return math.nan if math.isnan(value) != math.isnan(reference) else 0.0
    scale = max(abs(reference), ZERO_FLOOR_OF_PEAK * abs(peak))
    if scale == 0.0:
        return 0.0 if value == reference else math.inf
    return abs(value - reference) / scale


def _differs(value: float, reference: float, peak: float) -> bool:
    difference = _relative_difference(value, reference, peak)
    return math.isnan(difference) or difference > RELATIVE_TOLERANCE


def _size_text(size: float) -> str:
    """A size as a percentage (``12%``; two digits below 1%, ``0.62%``: a metric flagged
    against its own value can be that small on the response's scale, and ``0%`` read as no
    difference), or as a multiple from ``MULTIPLE_FROM`` on (``32x``)."""
    if size >= MULTIPLE_FROM:
        return f"{size:.0f}x"
    return f"{100 * size:.2g}%" if size < 0.01 else f"{size:.0%}"


def _response_size(metric: str, value: float, reference: dict[str, Any]) -> float:
    """How far a hybrid's metric is from its LQR's, on the response's scale: a deviation metric
    in units of the LQR's peak deviation (or of its own value, if larger), the settling time in
    units of the LQR's; 0 where either is NaN (a settling that one of them lacks is said, not
    sized)."""
    ref = reference[f"{metric}_mean"]
    if math.isnan(value) or math.isnan(ref):
        return 0.0
    scale = abs(ref) if metric == "settling_time" else max(abs(ref), abs(_peak(reference)))
    if scale == 0.0:
        return 0.0 if value == ref else math.inf
    return abs(value - ref) / scale


def _peak(row: dict[str, Any]) -> float:
    return row["peak_deviation_mean"]


def _response_failure(row: dict[str, Any], reference: dict[str, Any]) -> Failure | None:
    """A hybrid's response against its linear reference: None when it matches. Size: the
    largest difference of a flagged metric on the response's scale (:func:`_response_size`)."""
    subject = f"{row['system']} {label(row['controller'])} ({row['test']})"
    problems = []
    if row["n_terminated"] > 0:
        problems.append(f"terminated in {row['n_terminated']}/{row['n_runs']} runs")
    if row["n_settled"] < row["n_runs"]:
        problems.append(f"settled in only {row['n_settled']}/{row['n_runs']} runs")
    size, worst = 0.0, ""
    for metric in COMPARED_METRICS:
        value, ref = row[f"{metric}_mean"], reference[f"{metric}_mean"]
        if not _differs(value, ref, _peak(reference)):
            continue
        text = f"{metric.replace('_', ' ')} {number(value)} vs {number(ref)}"
        problems.append(text)
        metric_size = _response_size(metric, value, reference)
        if metric_size > size:
            size, worst = metric_size, text
    if not problems:
        return None
    return Failure(
        subject,
        size,
        f"off by {_size_text(size)}" if worst else problems[0],
        worst,
        f"**{row['system']} {label(row['controller'])}** ({row['test']}) differs from "
        f"{label(reference['controller'])}: " + "; ".join(problems) + ".",
    )


def _with_reference(rows: Rows, hybrids: bool) -> list[tuple[dict[str, Any], dict[str, Any]]]:
    """(row, its linear reference's row of the same system and test) for the hybrids' response
    tests (``hybrids``) or the learned baselines', in the rows' order; tests without a
    reference are left out."""
    index = {(r["system"], r["test"], r["controller"]): r for r in rows}
    pairs = []
    for (system, test, controller), row in index.items():
        if controller in LINEAR_CONTROLLERS or ("_hybrid" in controller) != hybrids:
            continue
        framework = controller_framework(controller)
        reference = index.get((system, test, LINEAR_REFERENCE.get(framework, "")))
        if reference is not None:
            pairs.append((row, reference))
    return pairs


def _response_failures(rows: Rows) -> tuple[int, list[Failure]]:
    """The hybrid response tests that have a linear reference, and those that differ from it
    by more than ``RELATIVE_TOLERANCE`` (relative) in a metric or settle/terminate where it does
    not, in the rows' order."""
    pairs = _with_reference(rows, hybrids=True)
    failures = [_response_failure(row, reference) for row, reference in pairs]
    return len(pairs), [failure for failure in failures if failure is not None]


#: The check: every hybrid's impulse and step responses match its LQR's (a flag per hybrid
#: response test that differs by more than ``RELATIVE_TOLERANCE`` in a metric, or
#: settles/terminates where the LQR does not).
RESPONSE_CHECK = Check(
    "responses",
    _response_failures,
    cases="hybrid response tests",
    threshold=f"each metric within {RELATIVE_TOLERANCE:.0%} of the LQR's; size: the "
    "largest difference against the LQR's peak deviation or settling time",
    worked="match their LQR",
)


def _baseline_without_offset(rows: Rows) -> tuple[int, list[Failure]]:
    """The baselines' response tests that have a linear reference, and those whose steady-state
    error is the reference's (as :func:`_differs` compares metrics): the cases
    where the paper's claim (iii), a baseline ends off the operating point, does not show. In
    the rows' order; size: 0 (nothing to rank)."""
    pairs = _with_reference(rows, hybrids=False)
    failures = []
    for row, reference in pairs:
        value, ref = row["steady_state_error_mean"], reference["steady_state_error_mean"]
        if _differs(value, ref, _peak(reference)):
            continue
        subject = f"{row['system']} {label(row['controller'])}"
        failures.append(
            Failure(
                f"{subject} ({row['test']})",
                0.0,
                f"steady state error {number(value)} vs {number(ref)}",
                "",
                f"**{subject}** ({row['test']}) ends where {label(reference['controller'])} does.",
            )
        )
    return len(pairs), failures


#: The paper's claim (iii) on the same rows (the headline table, :mod:`leoc.experiments.headline`):
#: every learned baseline's response ends off the LQR's end point, its mean steady-state error
#: differing from the LQR's as the response check compares metrics.
BASELINE_OFFSET_CHECK = Check(
    "responses",
    _baseline_without_offset,
    cases="baseline response tests",
    threshold=f"the steady-state error differs from the LQR's by more than "
    f"{RELATIVE_TOLERANCE:.0%} (of the LQR's, at least {ZERO_FLOOR_OF_PEAK:.0%} of its peak "
    "deviation)",
    worked="end off the operating point",
)


def _paper_pm(value: tuple[float, float] | None) -> str:
    """A paper's mean ± std; a std the paper prints negative is shown as its magnitude, marked."""
    if value is None:
        return "-"
    mean, std = value
    mark = NEGATIVE_STD_MARK if std < 0 else ""
    return f"{FMT.format(mean)} ± {FMT.format(abs(std))}{mark}"


def paper_cells(system: str, controller: str) -> list[str]:
    """The paper's appendix D row of a controller (three cells), '-' where it has none. The
    paper's single linear row belongs to the LQR at dt, not to the LQR at PILCO's period."""
    paper = PAPER_IMPULSE_METRICS.get(system, {}).get(controller)
    if paper is None:
        return ["-"] * PAPER_COLUMNS
    return [
        _paper_pm(paper.steady_state_error),
        _paper_pm(paper.overshoot),
        _paper_pm(paper.settling_time),
    ]


def _response_cells(row: dict[str, Any]) -> list[str]:
    return [
        row["system"],
        label(row["controller"]),
        str(row["action_repeat"]),
        pm(row["steady_state_error_mean"], row["steady_state_error_std"]),
        pm(row["overshoot_mean"], row["overshoot_std"]),
        pm(row["peak_deviation_mean"], row["peak_deviation_std"]),
        pm(row["settling_time_mean"], row["settling_time_std"]),
        number(row["settling_seconds_mean"]),
        f"{row['n_settled']}/{row['n_runs']}",
        f"{row['n_terminated']}/{row['n_runs']}",
    ]


def response_table(rows: Rows, test: str) -> list[str]:
    """The markdown table of one response test; the impulse table carries the paper's appendix
    D columns beside ours (the paper gives no step-response numbers)."""
    headers = list(RESPONSE_COLUMNS) + (list(PAPER_HEADERS) if test == "impulse" else [])
    table = []
    for row in rows:
        if row["test"] != test:
            continue
        cells = _response_cells(row)
        if test == "impulse":
            cells += paper_cells(row["system"], row["controller"])
        table.append(cells)
    lines = markdown_table(headers, table)
    paper = [cells[-PAPER_COLUMNS:] for cells in table] if test == "impulse" else []
    if any(cell.endswith(NEGATIVE_STD_MARK) for cells in paper for cell in cells):
        lines += ["", NEGATIVE_STD_NOTE]
    return lines


def compute(study: Study) -> dict[str, Any]:
    """The ``responses`` table (:func:`response_summary`)."""
    return {"responses": response_summary(study.evaluations)}


def _test_lines(rows: Rows, flags: list[str], test: str) -> list[str]:
    """What failed in one response test, then its table."""
    failed = [flag for flag in flags if f"({test})" in flag]
    return flag_block(failed, "no hybrid differs from its LQR.") + response_table(rows, test)


def render(report: Report) -> list[str]:
    """``## Impulse response`` and ``## Step response``: what failed, then the table."""
    rows, flags = report.tables["responses"], report.flags["responses"]
    return [
        "## Impulse response",
        "",
        *_test_lines(rows, flags, "impulse"),
        "",
        "## Step response",
        "",
        *_test_lines(rows, flags, "step"),
    ]


SECTION = Section(render, compute, RESPONSE_CHECK)
