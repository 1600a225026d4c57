"""The report's ``## Metric definitions``: the response tests, the metrics and the tolerance of
the hybrid-against-LQR check."""

from __future__ import annotations

from leoc.evaluation.metrics import DEFAULT_RELATIVE_BAND
from leoc.evaluation.rollout import IMPULSE_MAGNITUDE, STEP_MAGNITUDE
from leoc.experiments.report.base import Report, Section
from leoc.experiments.report.responses import RELATIVE_TOLERANCE, ZERO_FLOOR_OF_PEAK


def render(report: Report) -> list[str]:
    """The definitions (the same in every report)."""
    return [
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


SECTION = Section(render)
