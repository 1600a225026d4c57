"""The linear-controller report: LQR design and impulse/step metrics of every system.

This is the first stage of ``leoc reproduce``: it needs no training and runs in seconds.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from leoc.control import LQRDesign, design_lqr
from leoc.evaluation.metrics import ResponseMetrics
from leoc.evaluation.plots import plot_responses
from leoc.evaluation.rollout import RESPONSE_TESTS, ResponseResult, response_test
from leoc.experiments.markdown import markdown_table
from leoc.experiments.paper import PAPER_IMPULSE_METRICS
from leoc.io import write_json_atomic, write_text_atomic
from leoc.policies import LinearController
from leoc.systems import SYSTEM_NAMES, make_system

NUMBER_FORMAT = "{:.3g}"


def design_summary(design: LQRDesign) -> dict[str, Any]:
    """JSON-friendly view of an LQR design."""
    margins = design.margins
    return {
        "method": design.method,
        "K": design.K.tolist(),
        "W": design.W.tolist(),
        "b": design.b.tolist(),
        "A_d": design.A_d.tolist(),
        "B_d": design.B_d.tolist(),
        "Q": design.Q.tolist(),
        "R": design.R.tolist(),
        "closed_loop_eigenvalues": [[z.real, z.imag] for z in design.closed_loop_eigenvalues],
        "spectral_radius": design.spectral_radius,
        "gain_margin": margins.gain_margin,
        "phase_margin_deg": margins.phase_margin,
        "stable_gain_interval": list(margins.gain_interval),
    }


def format_settling(metrics: ResponseMetrics) -> str:
    """Settling time in steps as text, or ``not settled``."""
    return "not settled" if metrics.settling_time is None else str(metrics.settling_time)


def linear_responses(
    systems: Sequence[str] = SYSTEM_NAMES, method: str = "discrete"
) -> tuple[dict[str, LQRDesign], dict[str, dict[str, ResponseResult]]]:
    """Design the LQR of every system and run its impulse and step responses."""
    designs: dict[str, LQRDesign] = {}
    responses: dict[str, dict[str, ResponseResult]] = {}
    for name in systems:
        system = make_system(name)
        design = design_lqr(system, method=method)  # type: ignore[arg-type]
        controller = LinearController(design.W, design.b)
        designs[name] = design
        responses[name] = {test: response_test(system, controller, test) for test in RESPONSE_TESTS}
    return designs, responses


METRICS_HEADERS = (
    "system",
    "unit",
    "steady-state error",
    "overshoot",
    "settling time [steps]",
    "paper: steady-state error",
    "paper: overshoot",
    "paper: settling time",
)
"""Columns of :func:`metrics_table`."""
GAINS_HEADERS = (
    "system",
    "K (state)",
    "W (observation)",
    "spectral radius",
    "gain margin",
    "phase margin [deg]",
    "stable gain interval",
)
"""Columns of the linear report's gains table."""


def _gains_row(item: tuple[str, LQRDesign]) -> list[str]:
    """One system's cells of the gains table."""
    name, design = item
    low, high = design.margins.gain_interval
    return [
        name,
        np.array2string(design.K[0], precision=4),
        np.array2string(design.W[0], precision=4),
        f"{design.spectral_radius:.4f}",
        f"{design.margins.gain_margin:.3f}",
        f"{design.margins.phase_margin:.1f}",
        f"[{low:.3f}, {high:.3f}]",
    ]


def metrics_table(responses: dict[str, dict[str, ResponseResult]], test: str) -> list[str]:
    """Markdown rows: ours (linear) beside the paper's "Linear" row (impulse only)."""
    rows = []
    for name, by_test in responses.items():
        metrics = by_test[test].metrics
        unit = "deg" if make_system(name).main_in_degrees else "m"
        paper = PAPER_IMPULSE_METRICS[name]["linear"] if test == "impulse" else None
        paper_cells = (
            [
                NUMBER_FORMAT.format(paper.steady_state_error[0]),
                NUMBER_FORMAT.format(paper.overshoot[0]) if paper.overshoot else "-",
                NUMBER_FORMAT.format(paper.settling_time[0]),
            ]
            if paper
            else ["n/a", "n/a", "n/a"]
        )
        ours = [
            NUMBER_FORMAT.format(metrics.steady_state_error),
            NUMBER_FORMAT.format(metrics.overshoot),
            format_settling(metrics),
        ]
        rows.append([name, unit, *ours, *paper_cells])
    return markdown_table(METRICS_HEADERS, rows)


def write_linear_report(out_dir: str | Path, method: str = "discrete") -> Path:
    """Write ``linear_report.md``, ``linear.json`` and ``linear_responses.png`` to ``out_dir``.

    Returns the markdown path.
    """
    out = Path(out_dir)
    designs, responses = linear_responses(method=method)
    plot_responses(
        {
            name: {test: {"linear": [r.deviation]} for test, r in by_test.items()}
            for name, by_test in responses.items()
        },
        out / "linear_responses.png",
    )
    data = {
        name: {
            "design": design_summary(designs[name]),
            "responses": {
                test: {**result.metrics._asdict(), "deviation": result.deviation.tolist()}
                for test, result in responses[name].items()
            },
        }
        for name in designs
    }
    write_json_atomic(out / "linear.json", data)
    lines = ["# Linear (LQR) controllers", "", f"Design method: {method}.", ""]
    lines += ["## Gains", ""] + markdown_table(GAINS_HEADERS, map(_gains_row, designs.items()))
    for test in RESPONSE_TESTS:
        lines += ["", f"## {test.capitalize()} response (from the operating point)", ""]
        lines += metrics_table(responses, test)
    lines += ["", "![responses](linear_responses.png)", ""]
    path = out / "linear_report.md"
    write_text_atomic(path, "\n".join(lines))
    return path


# One field of the authors' variant switched back to leoc's value at a time (and the reverse
# from leoc's defaults), to measure which choice makes each difference in appendix D's Linear
# row: (label, base variant name, field, value).
#: The configurations of :func:`linear_row_ablation`: ``(label, base variant, field, value)``,
#: one field of a variant switched at a time.
LINEAR_ABLATION = (
    ("authors' variant (all its choices)", "authors", None, None),
    ("  with leoc's discrete LQR (gain x1, no u_max)", "authors", "lqr_method", "discrete"),
    ("  with leoc's clip instead of the sin squash", "authors", "linear_saturation", "none"),
    ("  with leoc's step rules (gymnasium pendulum)", "authors", "step_rules", {}),
    ("  with 200-step records", "authors", "response_steps", {}),
    ("leoc's defaults", "leoc", None, None),
    ("  with the authors' LQR (u_max K, their models)", "leoc", "lqr_method", "authors"),
    ("  with the continuous LQR on leoc's models", "leoc", "lqr_method", "continuous"),
)


class AblationRow(NamedTuple):
    """Impulse metrics of one linear configuration under both metric sets."""

    system: str
    label: str
    leoc: ResponseMetrics
    authors: ResponseMetrics


def linear_row_ablation(systems: Sequence[str] = SYSTEM_NAMES) -> list[AblationRow]:
    """The Linear row of appendix D under every configuration of :data:`LINEAR_ABLATION`:
    the impulse response of each system's linear reference, measured with leoc's and the
    authors' metric sets."""
    import dataclasses
    from types import MappingProxyType

    from leoc.experiments.variants import get_variant

    rows = []
    for name in systems:
        for label, base, field, value in LINEAR_ABLATION:
            variant = get_variant(base)
            if field is not None:
                if isinstance(value, dict):
                    value = MappingProxyType(value)
                variant = dataclasses.replace(variant, **{field: value})
            system = variant.system(name)
            controller = variant.linear_controller(system)
            steps = variant.steps_for(name)
            measured = [
                response_test(system, controller, "impulse", steps, metric_set=metric_set).metrics
                for metric_set in ("leoc", "authors")
            ]
            rows.append(AblationRow(name, label, *measured))
    return rows
