"""The report of ``leoc reproduce``, built only from the saved numbers (``leoc plot`` reruns it).

Outputs in the reproduce folder: ``results.json`` (every aggregated number), ``responses.csv``,
``robustness.csv``, ``learning_curves.csv``, ``learning_curves.png`` (paper figure 6),
``responses.png`` (figure 7), ``robustness.png`` (figure 8), ``relevance.png`` (figure 4) and
``report.md``.
"""

from __future__ import annotations

import json
import math
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from leoc.evaluation.metrics import DEFAULT_RELATIVE_BAND, ResponseMetrics, summarise_metrics
from leoc.evaluation.plots.basins import plot_basins_summary
from leoc.evaluation.plots.learning import plot_learning_curves
from leoc.evaluation.plots.relevance import plot_relevance
from leoc.evaluation.plots.responses import plot_responses
from leoc.evaluation.plots.robustness import plot_robustness
from leoc.evaluation.robustness import ROBUSTNESS_EPISODES, SCALED_PARAMETERS
from leoc.evaluation.rollout import IMPULSE_MAGNITUDE, RESPONSE_TESTS, STEP_MAGNITUDE
from leoc.experiments.animations import write_report_animations
from leoc.experiments.appendix_d import appendix_d_section
from leoc.experiments.claims_report import (
    hybrid_claims_section,
    roa_estimate_lines,
    roa_method_text,
)
from leoc.experiments.layout import (
    META_FILE,
    SWING_UP_EPISODES,
    Evaluations,
    load_evaluations,
)
from leoc.experiments.paper import PAPER_IMPULSE_METRICS
from leoc.experiments.profiles import (
    CONTROLLER_LABELS,
    CONTROLLERS,
    LINEAR_CONTROLLERS,
    LINEAR_REFERENCE,
)
from leoc.experiments.stats import (
    MIN_RUNS_FOR_INTERVAL,
    curve_bands,
    percent,
    probability_of_improvement,
    seed_summary,
    success_interval,
)
from leoc.experiments.summary import (
    CheckSummary,
    Failure,
    check_summary,
    summary_markdown,
    wall_time_text,
)
from leoc.io import write_csv_atomic, write_json_atomic, write_text_atomic
from leoc.names import FRAMEWORKS
from leoc.systems import make_system, system_names

CURVE_GRID_POINTS = 50
FMT = "{:.3g}"
# A hybrid "differs from its linear reference" when a metric differs by more than this fraction
# of the reference's value, with the reference floored at this fraction of its peak deviation
# (so 1e-12 vs 1e-13 of round-off in a zero steady-state error is not a difference).
RELATIVE_TOLERANCE = 0.01
ZERO_FLOOR_OF_PEAK = 0.01
COMPARED_METRICS = ("steady_state_error", "overshoot", "peak_deviation", "settling_time")
MULTIPLE_FROM = 10.0
"""A failure's size is shown as a multiple (``32x``) from this ratio on, as a percentage below."""


def _ordered(controllers: dict[str, Any]) -> list[str]:
    return [name for name in CONTROLLERS if name in controllers]


def _label(controller: str) -> str:
    return CONTROLLER_LABELS.get(controller, controller)


def _metrics(entry: dict[str, Any]) -> ResponseMetrics:
    return ResponseMetrics(**entry["metrics"])


def response_summary(evaluations: Evaluations) -> list[dict[str, Any]]:
    """Rows: system, test, controller, mean/std of the metrics over seeds, settled and
    terminated counts, settling time in seconds."""
    rows = []
    for system, by_controller in evaluations.items():
        dt = make_system(system).dt
        for test in RESPONSE_TESTS:
            for controller in _ordered(by_controller):
                runs = by_controller[controller]
                summary = summarise_metrics([_metrics(run["responses"][test]) for run in runs])
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


def robustness_summary(evaluations: Evaluations) -> list[dict[str, Any]]:
    """Rows: system, controller, parameter, scale, return mean/std over every episode of every
    seed, fraction stabilised, fraction of impulse tests settled."""
    rows = []
    for system, by_controller in evaluations.items():
        for controller in _ordered(by_controller):
            points: dict[tuple[str, float], list[dict[str, Any]]] = defaultdict(list)
            for run in by_controller[controller]:
                for point in run["robustness"]:
                    points[(point["parameter"], point["scale"])].append(point)
            for (parameter, scale), group in sorted(points.items()):
                returns = np.concatenate([p["returns"] for p in group])
                stabilised = np.concatenate([p["stabilised"] for p in group])
                impulses = [p["impulse"] for p in group]
                rows.append(
                    {
                        "system": system,
                        "controller": controller,
                        "parameter": parameter,
                        "scale": scale,
                        "return_mean": float(returns.mean()),
                        "return_std": float(returns.std()),
                        "fraction_stabilised": float(stabilised.mean()),
                        "impulse_settled": float(
                            np.mean([i["settled"] and not i["terminated"] for i in impulses])
                        ),
                        "n_episodes": int(returns.size),
                        "n_runs": len(group),
                    }
                )
    return rows


def swing_up_summary(evaluations: Evaluations) -> list[dict[str, Any]]:
    """Rows: system, controller, mean return and fraction of swing-up episodes that held, runs
    whose every episode held, mean hold step."""
    rows = []
    for system, by_controller in evaluations.items():
        for controller in _ordered(by_controller):
            runs = by_controller[controller]
            returns = np.concatenate([run["swing_up"]["returns"] for run in runs])
            holds = [h for run in runs for h in run["swing_up"]["hold_steps"]]
            held = [h for h in holds if h is not None]
            all_held = sum(run["swing_up"]["held_fraction"] >= 1.0 for run in runs)
            interval = success_interval(all_held, len(runs))
            rows.append(
                {
                    "system": system,
                    "controller": controller,
                    "return_mean": float(returns.mean()),
                    "return_std": float(returns.std()),
                    "fraction_held": len(held) / len(holds) if holds else 0.0,
                    "runs_all_held": all_held,
                    "runs_all_held_ci_low": interval[0],
                    "runs_all_held_ci_high": interval[1],
                    "n_runs": len(runs),
                    "mean_hold_step": float(np.mean(held)) if held else math.nan,
                }
            )
    return rows


def curve_summary(runs: list[dict[str, Any]]) -> dict[str, Any] | None:
    """Learning curves over seeds on a common grid (each seed's curve linearly interpolated;
    the grid spans the seconds all seeds reached): mean and std, and with at least three seeds
    the point-wise IQM with its 95 % bootstrap band (:func:`leoc.experiments.stats.curve_bands`).
    """
    curves = [run["curve"] for run in runs if run.get("curve") and run["curve"]["seconds"]]
    if not curves:
        return None
    end = min(curve["seconds"][-1] for curve in curves)
    start = max(curve["seconds"][0] for curve in curves)
    grid = np.linspace(start, end, CURVE_GRID_POINTS) if end > start else np.array([end])
    values = np.array([np.interp(grid, c["seconds"], c["returns"]) for c in curves])
    summary: dict[str, Any] = {
        "seconds": grid.tolist(),
        "mean": values.mean(0).tolist(),
        "std": values.std(0).tolist(),
        "n_seeds": len(curves),
    }
    if len(curves) >= MIN_RUNS_FOR_INTERVAL:
        bands = curve_bands(values)
        summary.update(
            iqm=np.asarray(bands.iqm).tolist(),
            ci_low=np.asarray(bands.ci_low).tolist(),
            ci_high=np.asarray(bands.ci_high).tolist(),
        )
    return summary


def first_hold_seconds(run: dict[str, Any]) -> float | None:
    """Interaction time of the first evaluation at which every episode held (None: never)."""
    curve = run.get("curve") or {}
    for seconds, held in zip(curve.get("seconds", []), curve.get("held_fraction", []), strict=True):
        if held >= 1.0:
            return float(seconds)
    return None


SEED_QUANTITIES = {
    "final return": lambda run: run["curve"]["returns"][-1] if run.get("curve") else None,
    "interaction time to first hold [s]": first_hold_seconds,
    "impulse steady-state error": lambda run: run["responses"]["impulse"]["metrics"][
        "steady_state_error"
    ],
    "impulse peak deviation": lambda run: run["responses"]["impulse"]["metrics"]["peak_deviation"],
    "impulse settling time [steps]": lambda run: run["responses"]["impulse"]["metrics"][
        "settling_time"
    ],
}


def seed_statistics(evaluations: Evaluations) -> list[dict[str, Any]]:
    """Rows: system, controller, quantity, IQM over seeds and its 95 % stratified-bootstrap
    interval (none with fewer than three seeds; the note says so), seeds used and missing (a
    run that never held or never settled has no value)."""
    rows = []
    for system, by_controller in evaluations.items():
        for controller in _ordered(by_controller):
            if controller in LINEAR_CONTROLLERS:
                continue
            runs = by_controller[controller]
            for quantity, value_of in SEED_QUANTITIES.items():
                summary = seed_summary([value_of(run) for run in runs])
                rows.append(
                    {
                        "system": system,
                        "controller": controller,
                        "quantity": quantity,
                        **summary._asdict(),
                    }
                )
    return rows


IMPROVEMENT_QUANTITIES = ("final return", "interaction time to first hold")


def _improvement_scores(
    quantity: str, hybrid: list[dict[str, Any]], baseline: list[dict[str, Any]]
) -> tuple[list[float], list[float]] | None:
    """Scores (higher is better) of both groups for ``quantity``, or None when a run lacks
    them. Interaction time: minus the seconds to the first hold; a run that never held ranks
    below every run that did, and ties with the others that never did (P(X > Y) depends on ranks
    only, so any value below all the others serves)."""
    if quantity == "final return":
        final = SEED_QUANTITIES["final return"]
        scores = [final(run) for run in hybrid], [final(run) for run in baseline]
        return None if None in scores[0] + scores[1] else scores
    runs = hybrid + baseline
    if any(not run.get("curve") for run in runs):
        return None
    never = -1.0 - max(max(run["curve"]["seconds"], default=0.0) for run in runs)

    def score(run: dict[str, Any]) -> float:
        seconds = first_hold_seconds(run)
        return never if seconds is None else -seconds

    return [score(run) for run in hybrid], [score(run) for run in baseline]


def improvement_rows(evaluations: Evaluations) -> list[dict[str, Any]]:
    """Probability that each hybrid (the paper's relevance and the ROA relevance) beats its
    framework's baseline: a higher final return, and the first hold after less interaction
    time (the paper's claim (ii)); :func:`~leoc.experiments.stats.probability_of_improvement`."""
    rows = []
    for system, by_controller in evaluations.items():
        for framework in FRAMEWORKS:
            baseline = by_controller.get(f"{framework}_baseline")
            for hybrid_name in (f"{framework}_hybrid", f"{framework}_hybrid_roa"):
                hybrid = by_controller.get(hybrid_name)
                if not hybrid or not baseline:
                    continue
                for quantity in IMPROVEMENT_QUANTITIES:
                    scores = _improvement_scores(quantity, hybrid, baseline)
                    if scores is None:
                        continue
                    estimate = probability_of_improvement(*scores)
                    rows.append(
                        {
                            "system": system,
                            "framework": framework,
                            "hybrid": hybrid_name,
                            "quantity": quantity,
                            **estimate._asdict(),
                        }
                    )
    return rows


def roa_summary(evaluations: Evaluations) -> list[dict[str, Any]]:
    """Rows: system, controller, its period, the certified rho and extent of the LQR at that
    period, the certified set's share of the basin box, and the controller's empirical basin:
    share of the box held, share of the certified set held (mean over seeds)."""
    rows = []
    for system, by_controller in evaluations.items():
        for controller in _ordered(by_controller):
            runs = [run for run in by_controller[controller] if run.get("roa")]
            if not runs:
                continue
            first = runs[0]["roa"]
            inside = [run["roa"]["certified_set_held"] for run in runs]
            rows.append(
                {
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
                    "basin_box_fraction": float(
                        np.mean([run["roa"]["basin_box_fraction"] for run in runs])
                    ),
                    "certified_set_held": None if None in inside else float(np.mean(inside)),
                    "n_runs": len(runs),
                }
            )
    return rows


def _roa_failures(rows: list[dict[str, Any]]) -> tuple[int, list[Failure]]:
    """The hybrids checked, and those whose empirical basin does not contain their LQR's
    certified set (size: the share of the set's starts not held), in the rows' order."""
    checked = [
        row
        for row in rows
        if "_hybrid" in row["controller"] and row["certified_set_held"] is not None
    ]
    return len(checked), [
        Failure(
            f"{row['system']} {_label(row['controller'])}",
            1.0 - row["certified_set_held"],
            f"holds {percent(row['certified_set_held'])}",
            "",
            f"**{row['system']} {_label(row['controller'])}** holds only "
            f"{percent(row['certified_set_held'])} of the starts in its LQR's certified region "
            "of attraction.",
        )
        for row in checked
        if row["certified_set_held"] < 1.0
    ]


def roa_check(rows: list[dict[str, Any]]) -> CheckSummary:
    """The region-of-attraction check: every hybrid holds its LQR's whole certified set."""
    return check_summary(
        *_roa_failures(rows),
        cases="hybrids",
        threshold="every start of its LQR's certified set held",
        worked="hold their LQR's whole certified set",
    )


def roa_flags(rows: list[dict[str, Any]]) -> list[str]:
    """Hybrids whose empirical basin does not contain their LQR's certified set."""
    return [failure.flag for failure in _roa_failures(rows)[1]]


# ------------------------------------------------------------------------------------ checks
def code_versions(evaluations: Evaluations) -> dict[str, list[str]]:
    """Run keys (``system/controller/seedN``) per leoc commit that produced them (``unknown``:
    a run written outside a git checkout or before runs recorded their versions)."""
    found: dict[str, list[str]] = defaultdict(list)
    for system, by_c in evaluations.items():
        for controller, runs in by_c.items():
            for run in runs:
                commit = (run.get("versions") or {}).get("leoc_commit", "unknown")
                found[commit].append(f"{system}/{controller}/seed{run['spec']['seed']}")
    return dict(sorted(found.items()))


def code_line(versions_found: dict[str, list[str]]) -> str:
    """One sentence on the code version(s) behind the runs; a mix is said plainly."""
    if not versions_found:
        return "Code: no runs."
    if len(versions_found) == 1:
        ((commit, runs),) = versions_found.items()
        return f"Code: all {len(runs)} runs from leoc commit `{commit}`."
    parts = "; ".join(f"`{c}`: {len(r)} runs" for c, r in versions_found.items())
    return (
        f"**Code: the runs come from {len(versions_found)} different leoc versions** ({parts}); "
        "their numbers are not from one version of the code."
    )


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
    """A size as a percentage (``12%``), or as a multiple from ``MULTIPLE_FROM`` on (``32x``)."""
    return f"{size:.0f}x" if size >= MULTIPLE_FROM else f"{size:.0%}"


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
    subject = f"{row['system']} {_label(row['controller'])} ({row['test']})"
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
        text = f"{metric.replace('_', ' ')} {_number(value)} vs {_number(ref)}"
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
        f"**{row['system']} {_label(row['controller'])}** ({row['test']}) differs from "
        f"{_label(reference['controller'])}: " + "; ".join(problems) + ".",
    )


def _response_failures(rows: list[dict[str, Any]]) -> tuple[int, list[Failure]]:
    """The hybrid response tests that have a linear reference, and those that differ from it
    by more than ``RELATIVE_TOLERANCE`` (relative) in a metric or settle/terminate where it does
    not, in the rows' order."""
    index = {(r["system"], r["test"], r["controller"]): r for r in rows}
    checked, failures = 0, []
    for (system, test, controller), row in index.items():
        framework = controller.split("_")[0]
        if controller in LINEAR_CONTROLLERS or "_hybrid" not in controller:
            continue
        reference = index.get((system, test, LINEAR_REFERENCE.get(framework, "")))
        if reference is None:
            continue
        checked += 1
        failure = _response_failure(row, reference)
        if failure is not None:
            failures.append(failure)
    return checked, failures


def response_check(rows: list[dict[str, Any]]) -> CheckSummary:
    """The response check: every hybrid's impulse and step responses match its LQR's."""
    return check_summary(
        *_response_failures(rows),
        cases="hybrid response tests",
        threshold=f"each metric within {RELATIVE_TOLERANCE:.0%} of the LQR's; size: the "
        "largest difference against the LQR's peak deviation or settling time",
        worked="match their LQR",
    )


def response_flags(rows: list[dict[str, Any]]) -> list[str]:
    """One sentence per hybrid whose response differs from its linear reference by more than
    1 % (relative) in a metric, or settles/terminates where the reference does not."""
    return [failure.flag for failure in _response_failures(rows)[1]]


def _robustness_failures(rows: list[dict[str, Any]]) -> tuple[int, list[Failure]]:
    """The hybrids' scaled parameters with a linear reference, and those at which the fraction
    of episodes stabilised differs from the reference's by more than ``RELATIVE_TOLERANCE``
    at some scale (size: the largest difference), in the rows' order."""
    index = {(r["system"], r["controller"], r["parameter"], r["scale"]): r for r in rows}
    checked: set[tuple[str, str, str]] = set()
    differing: dict[tuple[str, str, str, str], list[tuple[float, str]]] = defaultdict(list)
    for (system, controller, parameter, scale), row in sorted(index.items()):
        if "_hybrid" not in controller:
            continue
        reference_name = LINEAR_REFERENCE[controller.split("_")[0]]
        reference = index.get((system, reference_name, parameter, scale))
        if reference is None:
            continue
        checked.add((system, controller, parameter))
        ours, theirs = row["fraction_stabilised"], reference["fraction_stabilised"]
        if abs(ours - theirs) > RELATIVE_TOLERANCE:
            differing[(system, controller, parameter, reference_name)].append(
                (ours - theirs, f"x{scale:g} ({percent(ours)} vs {percent(theirs)})")
            )
    failures = []
    for (system, controller, parameter, reference), cells in differing.items():
        gap, cell = max(cells, key=lambda item: abs(item[0]))
        failures.append(
            Failure(
                f"{system} {_label(controller)}, {parameter}",
                abs(gap),
                f"{100 * gap:+.0f} pp at {cell.split(' (')[0]}",
                cell.split(" (")[1].rstrip(")"),
                f"**{system} {_label(controller)}**, {parameter} scaled: stabilises a different "
                f"fraction of episodes than {_label(reference)} at "
                + ", ".join(text for _, text in cells)
                + ".",
            )
        )
    return len(checked), failures


def robustness_check(rows: list[dict[str, Any]]) -> CheckSummary:
    """The robustness check: every hybrid stabilises the fraction of episodes its LQR does."""
    return check_summary(
        *_robustness_failures(rows),
        cases="hybrid x scaled-parameter sweeps",
        threshold=f"the share stabilised within {100 * RELATIVE_TOLERANCE:.0f} percentage "
        "point of the LQR's at every scale; size: the largest difference, + where the hybrid "
        "stabilises more",
        worked="stabilise as their LQR does at every scale",
    )


def robustness_flags(rows: list[dict[str, Any]]) -> list[str]:
    """Hybrids whose fraction stabilised differs from their linear reference's: one sentence
    per hybrid and scaled parameter, listing the scales where it does."""
    return [failure.flag for failure in _robustness_failures(rows)[1]]


def _swing_up_failures(rows: list[dict[str, Any]]) -> tuple[int, list[Failure]]:
    """The learned controllers, and those that do not swing up and hold in every episode (size:
    the share of episodes that did not hold), in the rows' order."""
    learned = [row for row in rows if row["controller"] not in LINEAR_CONTROLLERS]
    return len(learned), [
        Failure(
            f"{row['system']} {_label(row['controller'])}",
            1.0 - row["fraction_held"],
            f"{percent(row['fraction_held'])} held",
            "",
            f"**{row['system']} {_label(row['controller'])}** does not swing up and hold: "
            f"{percent(row['fraction_held'])} of its swing-up episodes held the operating point.",
        )
        for row in learned
        if row["fraction_held"] < 1.0
    ]


def swing_up_check(rows: list[dict[str, Any]]) -> CheckSummary:
    """The swing-up check: every learned controller swings up and holds in every episode."""
    return check_summary(
        *_swing_up_failures(rows),
        cases="learned controllers",
        threshold="every swing-up episode holds",
        worked="swing up and hold in every episode",
    )


def swing_up_flags(rows: list[dict[str, Any]]) -> list[str]:
    """Learned controllers that do not swing up and hold in every episode."""
    return [failure.flag for failure in _swing_up_failures(rows)[1]]


# ------------------------------------------------------------------------------------ figures
def relevance_traces(evaluations: Evaluations) -> dict[tuple[str, str], dict[str, Any]]:
    """The first seed's swing-up relevance trace of every hybrid, by (system, controller)."""
    return {
        (system, controller): runs[0]["relevance"]
        for system, by_controller in evaluations.items()
        for controller, runs in by_controller.items()
        if runs and runs[0].get("relevance")
    }


def write_relevance_figure(evaluations: Evaluations, path: Path) -> Path | None:
    """Figure 4 (``relevance.png``), or None when no run has a relevance trace."""
    traces = relevance_traces(evaluations)
    if not traces:
        return None
    names = list(dict.fromkeys(system for system, _ in traces))
    systems = {name: make_system(name) for name in names}
    return plot_relevance(
        traces,
        path,
        systems,
        [c for c in CONTROLLERS if any(c == k for _, k in traces)],
        {name: system.episode_steps * system.dt for name, system in systems.items()},
        CONTROLLER_LABELS,
    )


def _response_records(runs: list[dict[str, Any]], test: str) -> list[dict[str, Any]]:
    return [
        {
            "deviation": run["responses"][test]["deviation"],
            "terminated": run["responses"][test]["metrics"].get("terminated", False),
            "settled": run["responses"][test]["metrics"]["settled"],
        }
        for run in runs
    ]


# ------------------------------------------------------------------------------------ markdown
def _pm(mean: float, std: float) -> str:
    if math.isnan(mean):
        return "-"
    return f"{FMT.format(mean)} ± {FMT.format(std)}"


def _number(value: float) -> str:
    return "-" if math.isnan(value) else FMT.format(value)


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


def _table_row(cells: list[str]) -> str:
    return "| " + " | ".join(cells) + " |"


def response_table(rows: list[dict[str, Any]], test: str) -> list[str]:
    """The markdown table of one response test; the impulse table carries the paper's appendix
    D columns beside ours (the paper gives no step-response numbers)."""
    headers = list(RESPONSE_COLUMNS) + (list(PAPER_HEADERS) if test == "impulse" else [])
    lines = [_table_row(headers), "|" + "---|" * len(headers)]
    negative_std = False
    for row in rows:
        if row["test"] != test:
            continue
        cells = [
            row["system"],
            _label(row["controller"]),
            str(row["action_repeat"]),
            _pm(row["steady_state_error_mean"], row["steady_state_error_std"]),
            _pm(row["overshoot_mean"], row["overshoot_std"]),
            _pm(row["peak_deviation_mean"], row["peak_deviation_std"]),
            _pm(row["settling_time_mean"], row["settling_time_std"]),
            _number(row["settling_seconds_mean"]),
            f"{row['n_settled']}/{row['n_runs']}",
            f"{row['n_terminated']}/{row['n_runs']}",
        ]
        if test == "impulse":
            paper = paper_cells(row["system"], row["controller"])
            negative_std |= any(cell.endswith(NEGATIVE_STD_MARK) for cell in paper)
            cells += paper
        lines.append(_table_row(cells))
    if negative_std:
        lines += ["", NEGATIVE_STD_NOTE]
    return lines


def roa_table(rows: list[dict[str, Any]]) -> list[str]:
    """Markdown rows of the region-of-attraction table: certificate and empirical basins."""
    lines = [
        "| system | controller | period | certified rho (LQR at that period) | extent per state "
        "| certified share of the box | basin: box held | basin: certified set held |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        extent = ", ".join(FMT.format(value) for value in row["extent"])
        inside = "-" if row["certified_set_held"] is None else percent(row["certified_set_held"])
        lines.append(
            f"| {row['system']} | {_label(row['controller'])} | {row['action_repeat']} "
            f"| {FMT.format(row['rho'])} | ± [{extent}] | {percent(row['certified_box_fraction'])} "
            f"| {percent(row['basin_box_fraction'])} | {inside} |"
        )
    return lines


def robustness_table(rows: list[dict[str, Any]]) -> list[str]:
    """Per controller and parameter: fraction stabilised at each scale."""
    scales = sorted({r["scale"] for r in rows})
    lines = [
        "| system | controller | parameter | "
        + " | ".join(f"x{s:g}" for s in scales)
        + " | mean return |",
        "|---|---|---|" + "---|" * (len(scales) + 1),
    ]
    keys = list(dict.fromkeys((r["system"], r["controller"], r["parameter"]) for r in rows))
    for system, controller, parameter in keys:
        selected = {
            r["scale"]: r
            for r in rows
            if (r["system"], r["controller"], r["parameter"]) == (system, controller, parameter)
        }
        cells = [
            percent(selected[s]["fraction_stabilised"]) if s in selected else "" for s in scales
        ]
        mean_return = np.mean([r["return_mean"] for r in selected.values()])
        lines.append(
            f"| {system} | {_label(controller)} | {parameter} | "
            + " | ".join(cells)
            + f" | {FMT.format(mean_return)} |"
        )
    return lines


def swing_up_table(rows: list[dict[str, Any]]) -> list[str]:
    """Markdown rows of the swing-up table: return and hold test per controller."""
    lines = [
        "| system | controller | swing-up return | episodes holding the operating point "
        "| runs holding in every episode | its rate: 95% CI | mean hold step |",
        "|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        hold = "-" if math.isnan(row["mean_hold_step"]) else FMT.format(row["mean_hold_step"])
        lines.append(
            f"| {row['system']} | {_label(row['controller'])} "
            f"| {_pm(row['return_mean'], row['return_std'])} | {percent(row['fraction_held'])} "
            f"| {row['runs_all_held']}/{row['n_runs']} "
            f"| [{percent(row['runs_all_held_ci_low'])}, {percent(row['runs_all_held_ci_high'])}] "
            f"| {hold} |"
        )
    return lines


def _interval(low: float | None, high: float | None, note: str | None) -> str:
    if low is None or high is None:
        return f"({note})" if note else ""
    return f"[{FMT.format(low)}, {FMT.format(high)}]"


def seed_table(rows: list[dict[str, Any]]) -> list[str]:
    """Markdown rows of the seed statistics: IQM and 95% bootstrap interval per quantity."""
    lines = [
        "| system | controller | quantity | IQM | 95% CI | seeds used | seeds without a value |",
        "|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        centre = "-" if row["iqm"] is None else FMT.format(row["iqm"])
        interval = _interval(row["ci_low"], row["ci_high"], row["note"])
        lines.append(
            f"| {row['system']} | {_label(row['controller'])} | {row['quantity']} | {centre} "
            f"| {interval} | {row['n']} | {row['n_missing']} |"
        )
    return lines


def improvement_table(rows: list[dict[str, Any]]) -> list[str]:
    """Markdown rows of the probability that each hybrid beats its baseline."""
    lines = [
        "| system | hybrid | baseline | P(higher final return) | 95% CI | P(first hold sooner) "
        "| 95% CI |",
        "|---|---|---|---|---|---|---|",
    ]
    by_pair: dict[tuple[str, str, str], dict[str, dict[str, Any]]] = defaultdict(dict)
    for row in rows:
        key = (row["system"], row["hybrid"], f"{row['framework']}_baseline")
        by_pair[key][row["quantity"]] = row
    for (system, hybrid, baseline), found in by_pair.items():
        cells = [system, _label(hybrid), _label(baseline)]
        for quantity in IMPROVEMENT_QUANTITIES:
            row = found.get(quantity)
            if row is None:
                cells += ["-", "-"]
                continue
            cells.append("-" if row["probability"] is None else f"{row['probability']:.2f}")
            cells.append(_interval(row["ci_low"], row["ci_high"], row["note"]))
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def _flag_block(flags: list[str], none_text: str) -> list[str]:
    if not flags:
        return [f"**Checks: {none_text}**", ""]
    return ["**What failed:**", ""] + [f"- {flag}" for flag in flags] + [""]


def record_companion(out_dir: str | Path, other: str | Path) -> None:
    """Record in ``out_dir``'s ``meta.json`` the reproduce folder ``other`` (of the other
    implementation variant) whose runs the appendix-D table sets beside this folder's; stored
    relative to ``out_dir`` so that a published pair of folders keeps it.

    Raises
    ------
    FileNotFoundError
        Either folder has no ``meta.json``.
    ValueError
        Both folders hold the same variant.
    """
    import os

    out, companion = Path(out_dir), Path(other)
    metas = []
    for folder, name in ((out, "run_dir"), (companion, "compare")):
        if not (folder / META_FILE).is_file():
            raise FileNotFoundError(f"{name}: no {META_FILE} in {str(folder)!r}")
        metas.append(json.loads((folder / META_FILE).read_text()))
    variants = [meta.get("variant", "leoc") for meta in metas]
    if variants[0] == variants[1]:
        raise ValueError(
            f"compare: expected a folder of the other variant, found {variants[1]!r} in both"
        )
    metas[0]["compare"] = os.path.relpath(companion.resolve(), out.resolve())
    write_json_atomic(out / META_FILE, metas[0])


def write_report(out_dir: str | Path) -> Path:
    """Aggregate the finished runs of ``out_dir`` into numbers, figures and ``report.md``."""
    out = Path(out_dir)
    if not out.is_dir():
        raise FileNotFoundError(f"run_dir: the folder {str(out)!r} does not exist")
    meta_path = out / META_FILE
    if not meta_path.is_file():
        raise FileNotFoundError(
            f"run_dir: no {META_FILE} in {str(out)!r}; is it a reproduce folder?"
        )
    try:
        meta = json.loads(meta_path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as error:
        raise ValueError(f"{meta_path}: damaged reproduce metadata ({error})") from error
    evaluations = load_evaluations(out, meta)
    responses = response_summary(evaluations)
    robustness = robustness_summary(evaluations)
    swing_up = swing_up_summary(evaluations)
    curves = {
        system: {c: curve_summary(runs) for c, runs in by_c.items() if curve_summary(runs)}
        for system, by_c in evaluations.items()
    }
    run_seconds = sum(
        run["wall_seconds"]
        for by_c in evaluations.values()
        for runs in by_c.values()
        for run in runs
    )
    seeds = seed_statistics(evaluations)
    roa = roa_summary(evaluations)
    improvements = improvement_rows(evaluations)
    flags = {
        "responses": response_flags(responses),
        "robustness": robustness_flags(robustness),
        "swing_up": swing_up_flags(swing_up),
        "roa": roa_flags(roa),
    }
    checks = {
        "responses": response_check(responses).to_json(),
        "robustness": robustness_check(robustness).to_json(),
        "swing_up": swing_up_check(swing_up).to_json(),
        "roa": roa_check(roa).to_json(),
    }
    write_json_atomic(
        out / "results.json",
        {
            "meta": meta,
            "responses": responses,
            "robustness": robustness,
            "swing_up": swing_up,
            "seed_statistics": seeds,
            "region_of_attraction": roa,
            "probability_of_improvement": improvements,
            "learning_curves": curves,
            "flags": flags,
            "checks": checks,
            "summed_run_wall_seconds": run_seconds,
            "code_versions": code_versions(evaluations),
        },
    )
    write_csv_atomic(out / "responses.csv", responses)
    write_csv_atomic(out / "robustness.csv", robustness)
    write_csv_atomic(out / "swing_up.csv", swing_up)
    write_csv_atomic(out / "seed_statistics.csv", seeds)
    curve_rows = [
        {"system": s, "controller": c, "seconds": t, "mean": m, "std": d}
        for s, by_c in curves.items()
        for c, curve in by_c.items()
        for t, m, d in zip(curve["seconds"], curve["mean"], curve["std"], strict=True)
    ]
    write_csv_atomic(out / "learning_curves.csv", curve_rows)
    figures = []
    if evaluations:
        plot_responses(
            {
                system: {
                    test: {c: _response_records(runs, test) for c, runs in by_c.items()}
                    for test in RESPONSE_TESTS
                }
                for system, by_c in evaluations.items()
            },
            out / "responses.png",
            CONTROLLER_LABELS,
        )
        figures.append(("Impulse and step responses (paper figure 7)", "responses.png"))
    if any(curves.values()):
        plot_learning_curves(curves, out / "learning_curves.png", CONTROLLER_LABELS)
        figures.append(("Learning curves (paper figure 6)", "learning_curves.png"))
    if robustness:
        plot_robustness(
            robustness, out / "robustness.png", CONTROLLERS, SCALED_PARAMETERS, CONTROLLER_LABELS
        )
        figures.append(("Robustness (paper figure 8)", "robustness.png"))
    if roa:
        plot_basins_summary(roa, out / "basins.png", CONTROLLER_LABELS)
        figures.append(("Empirical basins and the certified region of attraction", "basins.png"))
    if write_relevance_figure(evaluations, out / "relevance.png"):
        figures.append(("Relevance along a swing-up (paper figure 4)", "relevance.png"))
    for system, animation in write_report_animations(out, evaluations).items():
        figures.append(
            (
                f"{system}: a hybrid's swing-up and impulse response, r(x) shown",
                animation.relative_to(out).as_posix(),
            )
        )
    path = out / "report.md"
    document = render_markdown(
        meta,
        evaluations,
        {
            "responses": responses,
            "robustness": robustness,
            "swing_up": swing_up,
            "seeds": seeds,
            "improvements": improvements,
            "roa": roa,
        },
        flags,
        figures,
        run_seconds,
        appendix_d_section(out, meta, evaluations),
        checks,
    )
    write_text_atomic(path, document)
    return path


def invocations_lines(invocations: Sequence[dict[str, Any]] | None) -> list[str]:
    """The report's line on a folder resumed over several invocations (``meta.json``'s
    ``invocations``), followed by a blank line; nothing for a folder of one invocation.

    An invocation that ended without a word (``ended`` ``"lost"``: killed, or its machine lost)
    counts its wall time up to its last finished run; the line says so."""
    if not invocations or len(invocations) < 2:
        return []
    parts = [
        f"{item.get('started_utc', '?')}: {item.get('wall_seconds', 0):.0f} s, "
        f"{item.get('runs_finished', '?')} runs finished"
        + _how_it_ended(item)
        + (f", commit {item['leoc_commit']}" if item.get("leoc_commit") else "")
        for item in invocations
    ]
    total = sum(item.get("wall_seconds", 0) for item in invocations)
    lost = any(item.get("ended") == "lost" for item in invocations)
    return [
        f"Resumed over {len(invocations)} invocations ({total:.0f} s of wall time in all"
        + ("; a lost invocation counts up to its last finished run" if lost else "")
        + "): "
        + "; ".join(parts)
        + ".",
        "",
    ]


def _how_it_ended(item: dict[str, Any]) -> str:
    ended = item.get("ended")
    if ended == "lost":
        return ", lost (ended without a word: killed, or its machine lost)"
    if ended == "running":
        return ", running"
    return ", interrupted" if item.get("interrupted") else ""


def machine_line(machine: dict[str, Any] | None) -> str:
    """The report's line on the machine of the last invocation (``meta.json``'s ``machine``)."""
    if not machine:
        return "Machine: not recorded (a run folder written before leoc recorded it)."
    memory = machine.get("memory_gib")
    return (
        f"Machine of the last invocation: {machine.get('cpu', 'unknown CPU')}, "
        f"{machine.get('logical_cpus', '?')} logical CPUs"
        + (f", {memory} GiB memory" if memory is not None else "")
        + f", {machine.get('platform', 'unknown platform')}"
        + (
            f", torch's {machine['torch_cpu_capability']} kernels"
            if machine.get("torch_cpu_capability")
            else ""
        )
        + "."
    )


SELECTION_RULES = {
    "final": "the final controller (at the end of its training budget)",
    "best_held": "the evaluation that held the operating point in the most episodes, the "
    "highest mean return among those",
    "best_last_third": "the evaluation of highest mean return in the last third of training",
}
"""What each recorded ``model_selection`` rule returns (:mod:`leoc.ddpg.callbacks`); PILCO's
selecting rule records its own sentence."""
NOT_RECORDED = "not recorded"


def recorded_selection(run: dict[str, Any]) -> str:
    """The model selection a run recorded (its curve's ``model_selection``; a PILCO selection's
    iteration dropped, so runs of one rule group together), or ``NOT_RECORDED``."""
    rule = str((run.get("curve") or {}).get("model_selection") or NOT_RECORDED)
    return rule.split(" (iteration ")[0]


def model_selection_text(evaluations: Evaluations) -> str:
    """The report's sentence on model selection, from what each learned run recorded: per
    learner and rule, the runs and what the rule returns; runs that select on their trainer's
    evaluation episodes are said to (their starts are the first of the swing-up table's)."""
    groups: dict[tuple[str, str], int] = defaultdict(int)
    for by_controller in evaluations.values():
        for controller, runs in by_controller.items():
            if controller in LINEAR_CONTROLLERS:
                continue
            for run in runs:
                groups[(controller.split("_")[0].upper(), recorded_selection(run))] += 1
    if not groups:
        return "Model selection: none (linear controllers only: designed, not trained)."
    parts = [
        f"{learner} ({count} run{'s' if count > 1 else ''}): "
        + (f"`{rule}`, {SELECTION_RULES[rule]}" if rule in SELECTION_RULES else rule)
        for (learner, rule), count in sorted(groups.items())
    ]
    text = "Model selection, as each run recorded it: " + "; ".join(parts) + "."
    if any(rule not in ("final", NOT_RECORDED) for _, rule in groups):
        text += (
            " A rule other than `final` selects on the trainer's evaluation episodes, whose "
            "seeded starts are the first of the swing-up table's: that table is optimistic "
            "for those runs."
        )
    if any(rule == NOT_RECORDED for _, rule in groups):
        text += (
            " 'Not recorded': runs written before leoc kept each run's selection (in its "
            "curve's model_selection)."
        )
    return text


def _has_sac(evaluations: Evaluations) -> bool:
    return any(c.startswith("sac_") for by_c in evaluations.values() for c in by_c)


def _dt_hybrids(evaluations: Evaluations) -> str:
    """The hybrids compared with the LQR at dt: DDPG's, and SAC's when the report has them."""
    return "DDPG and SAC hybrids" if _has_sac(evaluations) else "DDPG hybrids"


def _sac_note(evaluations: Evaluations) -> str:
    """What a SAC controller is, said only in a report that has one."""
    if not _has_sac(evaluations):
        return ""
    return (
        " A SAC controller is SAC's deterministic action (its squashed mean), trained at the "
        "DDPG budgets."
    )


def render_markdown(
    meta: dict[str, Any],
    evaluations: Evaluations,
    tables: dict[str, list[dict[str, Any]]],
    flags: dict[str, list[str]],
    figures: list[tuple[str, str]],
    run_seconds: float,
    appendix: list[str] | None = None,
    checks: dict[str, dict[str, Any]] | None = None,
) -> str:
    """The markdown of ``report.md``; ``appendix`` (the appendix-D section of
    :mod:`leoc.experiments.appendix_d`) goes before the response tables; ``checks`` (per
    report section, :meth:`leoc.experiments.summary.CheckSummary.to_json`) make the summary."""
    responses, robustness = tables["responses"], tables["robustness"]
    wall = wall_time_text(meta)
    lines = [
        "# LEOC: reproduction of Zhang & Capel (L4DC 2021)",
        "",
        f"**Profile: {meta.get('profile')}** ({meta.get('description', '')}).",
        "",
        f"Seeds: {meta.get('seeds')}. Settings: `{json.dumps(meta.get('settings'))}`.",
        "",
        f"Wall time: {wall}; summed wall time of all runs: {run_seconds:.0f} s (runs "
        f"execute in parallel on {meta.get('jobs')} workers)."
        if wall is not None
        else "Wall time: not finished.",
        "",
        *invocations_lines(meta.get("invocations")),
        "Versions: " + ", ".join(f"{k} {v}" for k, v in meta.get("versions", {}).items()),
        "",
        machine_line(meta.get("machine")),
        "",
        code_line(code_versions(evaluations)),
        "",
        f"{model_selection_text(evaluations)} Every controller is evaluated at the control "
        "period it was trained at (the 'period' column: simulator steps per decision; PILCO "
        "holds each action for that many steps), and each hybrid is compared with the LQR "
        f"designed for its own period: {_dt_hybrids(evaluations)} with *linear (LQR at dt)*, "
        "PILCO hybrids with *linear (LQR at PILCO's period)*." + _sac_note(evaluations),
        "",
    ]
    aggregated = "; ".join(
        f"{system}/{controller}: seeds {sorted(run['spec']['seed'] for run in runs)}"
        for system, by_controller in evaluations.items()
        for controller, runs in by_controller.items()
    )
    lines += [f"Runs aggregated in this report: {aggregated or 'none'}.", ""]
    missing = [
        f"{s}/{c}"
        for s in meta.get("systems", [])
        for c in meta.get("controllers", [])
        if c not in evaluations.get(s, {})
    ]
    if missing:
        lines += [f"Runs without results (failed or not run yet): {', '.join(missing)}.", ""]
    lines += summary_markdown(checks or {}, missing)
    lines += [
        "## Metric definitions",
        "",
        f"Every response test starts exactly at the operating point; *impulse* adds "
        f"{IMPULSE_MAGNITUDE:g} to the action of the first simulator step, *step* adds "
        f"{STEP_MAGNITUDE:g} to every action, for 200 simulator steps. e(t) is the deviation of "
        "the main coordinate (degrees for pendulum and cart-pole, metres for mountain car).",
        "- steady-state error: mean of e over the last 20 samples;",
        "- overshoot: largest excursion past that final value on the side opposite to the "
        "initial deviation (the side of the first sample deviating by more than 1% of the "
        "peak deviation);",
        "- peak deviation: max |e(t)| (what the paper's 'overshoot' column appears to be: its "
        "'Linear' values equal the first swing of the impulse in our simulators);",
        f"- settling time: first step after which |e - e_final| stays within the band to the "
        f"end, the band being {DEFAULT_RELATIVE_BAND:.0%} of the peak error max |e - e_final| "
        "(MATLAB stepinfo's convention); *not settled* (no number) if a sample of the last 20 "
        "is outside it; reported in steps and seconds;",
        "- terminated: the episode left the allowed region (its record is cut short).",
        "Mean ± std (population) over seeds; settling time over the settled runs only. A hybrid "
        f"is flagged when a metric differs from its linear reference by more than "
        f"{RELATIVE_TOLERANCE:.0%} of the reference (floored at {ZERO_FLOOR_OF_PEAK:.0%} of its "
        "peak deviation, so round-off around zero is not a difference).",
        "",
        "The paper's numbers (appendix D, typed in) do not state their band; its mountain-car "
        "settling times (~201 steps) exceed the 200-step episode.",
        "",
    ]
    lines += appendix or []
    lines += [
        "## Impulse response",
        "",
    ]
    lines += _flag_block(
        [f for f in flags["responses"] if "(impulse)" in f], "no hybrid differs from its LQR."
    )
    lines += response_table(responses, "impulse")
    lines += ["", "## Step response", ""]
    lines += _flag_block(
        [f for f in flags["responses"] if "(step)" in f], "no hybrid differs from its LQR."
    )
    lines += response_table(responses, "step")
    regions = "; ".join(
        f"{s}: ± {list(make_system(s).operating_region)} ({', '.join(make_system(s).state_names)})"
        for s in system_names()
        if s in evaluations
    )
    lines += [
        "",
        "## Robustness",
        "",
        "Each controller, trained on the nominal system, runs on systems whose mass (all "
        "masses) or g is scaled by 0.5x ... 5.0x: per scale and seed, "
        f"{ROBUSTNESS_EPISODES} episodes from starts drawn uniformly in the operating region "
        f"(the same starts at every scale; {regions}; the nominal LQR recovers from every "
        "corner of these boxes), and the impulse test. Cells: fraction of episodes stabilised "
        "(held the operating point within the hold band for the system's minimum duration at "
        "the end, not terminated). Large scales fail for physical reasons: the actuator limit "
        "cannot hold the heavier or stronger-pulled system away from the top.",
        "",
    ]
    lines += _flag_block(flags["robustness"], "every hybrid stabilises as its LQR does.")
    lines += robustness_table(robustness)
    lines += [
        "",
        "## Swing-up",
        "",
        f"{SWING_UP_EPISODES} episodes per run from the seeded swing-up starts (the trainers' "
        "evaluation starts). Linear controllers are not expected to swing up. A run succeeds "
        "when it holds in every episode; 'its rate: 95% CI' is the Clopper-Pearson interval of "
        "that success rate over the runs (5 of 5 gives [48%, 100%]: a handful of seeds bounds a "
        "rate only loosely).",
        "",
    ]
    lines += _flag_block(flags["swing_up"], "every learned controller swings up and holds.")
    lines += swing_up_table(tables["swing_up"])
    lines += [
        "",
        "## Region of attraction",
        "",
        roa_method_text(evaluations)
        + "controller's empirical basin: the share of seeded starts in the basin box, and of "
        "starts uniform in that certified set, that converge and hold. A hybrid whose basin "
        "contains the set holds 100% of the latter.",
        "",
    ]
    if tables["roa"]:
        first = tables["roa"][0]
        lines += roa_estimate_lines(evaluations, first)
    lines += _flag_block(flags["roa"], "every hybrid holds its LQR's whole certified set.")
    lines += roa_table(tables["roa"])
    lines += hybrid_claims_section(evaluations)
    n_seeds = len(meta.get("seeds", []))
    lines += [
        "",
        "## Seed statistics",
        "",
        "Interquartile mean (IQM) over seeds and its 95% stratified-bootstrap confidence "
        "interval (Agarwal et al. 2021, 'Deep RL at the edge of the statistical precipice'; "
        "`leoc.experiments.stats`). 'final return': the last evaluation of the learning curve; "
        "'interaction time to first hold': the first evaluation at which every episode held "
        "(a seed that never held has no value and is counted as without one).",
        "",
    ]
    if n_seeds < MIN_RUNS_FOR_INTERVAL:
        lines += [
            f"With {n_seeds} seed(s) there are no intervals (at least "
            f"{MIN_RUNS_FOR_INTERVAL} are needed); the IQM of one value is that value.",
            "",
        ]
    elif n_seeds < 4:
        lines += [
            f"With {n_seeds} seeds the IQM trims nothing (it is the mean) and the bootstrap has "
            "few distinct resamples: read the intervals as rough.",
            "",
        ]
    lines += seed_table(tables["seeds"])
    lines += [
        "",
        "Probability that a run of the hybrid beats a run of its baseline (Mann-Whitney, "
        "ties count half; 95% stratified-bootstrap interval): a higher final return, and the "
        "first hold after less interaction time, a run that never held ranking below every run "
        "that did (the paper's claim that the hybrid needs similar or less interaction time).",
        "",
    ]
    lines += improvement_table(tables["improvements"])
    for title, filename in figures:
        lines += ["", f"## {title}", "", f"![{title}]({filename})"]
    lines += [
        "",
        "All numbers: results.json, responses.csv, robustness.csv, swing_up.csv, "
        "learning_curves.csv. Regenerate figures and this report: `leoc plot <folder>`.",
        "",
    ]
    return "\n".join(lines)
