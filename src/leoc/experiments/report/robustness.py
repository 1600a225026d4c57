"""The report's robustness: each controller on systems with scaled masses or g, and the check
that every hybrid stabilises the share of episodes its LQR does."""

from __future__ import annotations

from collections import defaultdict
from typing import Any

import numpy as np

from leoc.evaluation.robustness import ROBUSTNESS_EPISODES, SCALE_FACTORS
from leoc.experiments.layout import Evaluations
from leoc.experiments.markdown import markdown_table
from leoc.experiments.profiles import LINEAR_REFERENCE
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
from leoc.experiments.report.responses import RELATIVE_TOLERANCE
from leoc.experiments.stats import percent
from leoc.experiments.summary import Failure
from leoc.names import controller_framework
from leoc.systems import make_system, system_names


def _row(
    system: str, controller: str, parameter: str, scale: float, group: list[dict[str, Any]]
) -> dict[str, Any]:
    """One controller at one scale of one parameter, over every episode of every seed."""
    returns = np.concatenate([p["returns"] for p in group])
    stabilised = np.concatenate([p["stabilised"] for p in group])
    impulses = [p["impulse"] for p in group]
    return {
        "system": system,
        "controller": controller,
        "parameter": parameter,
        "scale": scale,
        "return_mean": float(returns.mean()),
        "return_std": float(returns.std()),
        "fraction_stabilised": float(stabilised.mean()),
        "impulse_settled": float(np.mean([i["settled"] and not i["terminated"] for i in impulses])),
        "n_episodes": int(returns.size),
        "n_runs": len(group),
    }


def robustness_summary(evaluations: Evaluations) -> Rows:
    """Rows: system, controller, parameter, scale, return mean/std over every episode of every
    seed, fraction stabilised, fraction of impulse tests settled."""
    rows = []
    for system, by_controller in evaluations.items():
        for controller in ordered(by_controller):
            points: dict[tuple[str, float], list[dict[str, Any]]] = defaultdict(list)
            for run in by_controller[controller]:
                for point in run["robustness"]:
                    points[(point["parameter"], point["scale"])].append(point)
            for (parameter, scale), group in sorted(points.items()):
                rows.append(_row(system, controller, parameter, scale, group))
    return rows


def _sweep_gaps(rows: Rows) -> tuple[int, dict[tuple[str, str, str, str], list]]:
    """The hybrids' scaled parameters with a linear reference (how many), and for each the
    scales at which the fraction of episodes stabilised differs from the reference's by more
    than ``RELATIVE_TOLERANCE``: (hybrid's minus reference's, ``"xSCALE (ours vs theirs)"``),
    keyed by (system, controller, parameter, reference), in the rows' order."""
    index = {(r["system"], r["controller"], r["parameter"], r["scale"]): r for r in rows}
    checked: set[tuple[str, str, str]] = set()
    differing: dict[tuple[str, str, str, str], list[tuple[float, str]]] = defaultdict(list)
    for (system, controller, parameter, scale), row in sorted(index.items()):
        if "_hybrid" not in controller:
            continue
        reference_name = LINEAR_REFERENCE[controller_framework(controller)]
        reference = index.get((system, reference_name, parameter, scale))
        if reference is None:
            continue
        checked.add((system, controller, parameter))
        ours, theirs = row["fraction_stabilised"], reference["fraction_stabilised"]
        if abs(ours - theirs) > RELATIVE_TOLERANCE:
            differing[(system, controller, parameter, reference_name)].append(
                (ours - theirs, f"x{scale:g} ({percent(ours)} vs {percent(theirs)})")
            )
    return len(checked), differing


def _gap_failures(differing: dict[tuple[str, str, str, str], list], verb: str) -> list[Failure]:
    """A failure per sweep of ``differing`` (size: its largest difference), whose flag says the
    hybrid ``verb`` (a fraction of episodes) than its reference at the scales listed."""
    failures = []
    for (system, controller, parameter, reference), cells in differing.items():
        gap, cell = max(cells, key=lambda item: abs(item[0]))
        failures.append(
            Failure(
                f"{system} {label(controller)}, {parameter}",
                abs(gap),
                f"{100 * gap:+.0f} pp at {cell.split(' (')[0]}",
                cell.split(" (")[1].rstrip(")"),
                f"**{system} {label(controller)}**, {parameter} scaled: {verb} fraction of "
                f"episodes than {label(reference)} at "
                + ", ".join(text for _, text in cells)
                + ".",
            )
        )
    return failures


def _robustness_failures(rows: Rows) -> tuple[int, list[Failure]]:
    """The hybrids' scaled parameters with a linear reference, and those at which the fraction
    of episodes stabilised differs from the reference's by more than ``RELATIVE_TOLERANCE``
    at some scale (size: the largest difference), in the rows' order."""
    checked, differing = _sweep_gaps(rows)
    return checked, _gap_failures(differing, "stabilises a different")


def _robustness_deficits(rows: Rows) -> tuple[int, list[Failure]]:
    """The hybrids' scaled parameters with a linear reference, and those at which the hybrid
    stabilises a smaller fraction of episodes than its reference, by more than
    ``RELATIVE_TOLERANCE``, at some scale (size: the largest deficit), in the rows' order."""
    checked, differing = _sweep_gaps(rows)
    deficits = {key: [c for c in cells if c[0] < 0] for key, cells in differing.items()}
    return checked, _gap_failures({k: v for k, v in deficits.items() if v}, "stabilises a smaller")


#: The check: every hybrid stabilises the share of episodes its LQR does at every scale (a
#: flag per hybrid and scaled parameter, listing the scales where it does not).
ROBUSTNESS_CHECK = Check(
    "robustness",
    _robustness_failures,
    cases="hybrid x scaled-parameter sweeps",
    threshold=f"the share stabilised within {100 * RELATIVE_TOLERANCE:.0f} percentage "
    "point of the LQR's at every scale; size: the largest difference, + where the hybrid "
    "stabilises more",
    worked="stabilise as their LQR does at every scale",
)
#: The claim's side of it (the headline table, :mod:`leoc.experiments.headline`): every hybrid
#: stabilises at least the share of episodes its LQR does at every scale.
ROBUSTNESS_DEFICIT_CHECK = Check(
    "robustness",
    _robustness_deficits,
    cases="hybrid x scaled-parameter sweeps",
    threshold=f"the share stabilised at least the LQR's less {100 * RELATIVE_TOLERANCE:.0f} "
    "percentage point at every scale; size: the largest deficit",
    worked="stabilise at least the share their LQR does at every scale",
)


def robustness_table(rows: Rows) -> list[str]:
    """Per controller and parameter: fraction stabilised at each scale."""
    scales = sorted({r["scale"] for r in rows})
    table = []
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
        table.append([system, label(controller), parameter, *cells, FMT.format(mean_return)])
    headers = ["system", "controller", "parameter", *(f"x{s:g}" for s in scales), "mean return"]
    return markdown_table(headers, table)


def compute(study: Study) -> dict[str, Any]:
    """The ``robustness`` table (:func:`robustness_summary`)."""
    return {"robustness": robustness_summary(study.evaluations)}


def _scales_in_words(rows: list[dict[str, Any]]) -> str:
    """The table's scales (for an empty table the default sweep's,
    :data:`~leoc.evaluation.robustness.SCALE_FACTORS`): ``0.5x ... 5.0x`` for a run of evenly
    spaced ones, else each (``0.5x, 1x, 5x``: a profile's reduced grid)."""
    scales = sorted({row["scale"] for row in rows}) or list(SCALE_FACTORS)
    steps = np.diff(scales)
    if len(scales) > 3 and np.allclose(steps, steps[0]):
        return f"{scales[0]:.1f}x ... {scales[-1]:.1f}x"
    return ", ".join(f"{scale:g}x" for scale in scales)


def render(report: Report) -> list[str]:
    """``## Robustness``: the protocol, what failed, the table."""
    evaluations = report.study.evaluations
    regions = "; ".join(
        f"{s}: ± {list(make_system(s).operating_region)} ({', '.join(make_system(s).state_names)})"
        for s in system_names()
        if s in evaluations
    )
    return [
        "",
        "## Robustness",
        "",
        "Each controller, trained on the nominal system, runs on systems whose mass (all "
        f"masses) or g is scaled by {_scales_in_words(report.tables['robustness'])}: per "
        "scale and seed, "
        f"{ROBUSTNESS_EPISODES} episodes from starts drawn uniformly in the operating region "
        f"(the same starts at every scale; {regions}; the nominal LQR recovers from every "
        "corner of these boxes), and the impulse test. Cells: fraction of episodes stabilised "
        "(held the operating point within the hold band for the system's minimum duration at "
        "the end, not terminated). Large scales fail for physical reasons: the actuator limit "
        "cannot hold the heavier or stronger-pulled system away from the top.",
        "",
        *flag_block(report.flags["robustness"], "every hybrid stabilises as its LQR does."),
        *robustness_table(report.tables["robustness"]),
    ]


SECTION = Section(render, compute, ROBUSTNESS_CHECK)
