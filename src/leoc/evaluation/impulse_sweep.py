r"""Impulse responses swept from the paper's size up to the size at which the LQR fails.

The paper's impulse test adds -1 to the first action only (:mod:`leoc.evaluation.rollout`).
The actuator clips that action, so a one-step impulse can never be large: from the operating
point the LQR recovers from it on every paper system, and a hybrid whose relevance stays 1 along
the response is its LQR step for step. Such a comparison holds *by construction*.

Here a disturbance of size :math:`m` is an action offset whose integral is :math:`-m`
(action units times steps): one step of :math:`-m` while :math:`m \le A` (so :math:`m = 1` is
the paper's test), and beyond that :math:`\lfloor m / A \rfloor` steps of :math:`-A` followed
by the remainder, with :math:`A = 2 u_{\max}` (``PULSE_AMPLITUDE`` times the actuator limit):
an offset that large drives the clipped action to :math:`-u_{\max}` whatever the controller
asks, so a larger one-step amplitude would change nothing and the disturbance grows by lasting
longer. The LQR's *failure size* :math:`m^*` is the smallest size (to ``FAILURE_TOLERANCE``, by
bisection after doubling) whose response does not end holding the operating point
(``System.hold_step``). A sweep runs sizes from 1 to :math:`m^*` and records, per size and
controller, whether it held, the settling time and the least relevance
:math:`\min_t r(x_t)` along the response: a hybrid comparison is *by construction* at a size
where that minimum is exactly 1 (the hybrid applied :math:`G` throughout) and *evidence*
otherwise.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from leoc.evaluation.metrics import response_metrics
from leoc.systems.base import System
from leoc.systems.rollout import Controller, hold_step, rollout

__all__ = [
    "ImpulsePoint",
    "impulse_offsets",
    "impulse_sweep",
    "lqr_failure_size",
    "pulse_amplitude",
    "sweep_sizes",
]

PAPER_SIZE = 1.0
"""The paper's impulse: an offset of -1 on the first action."""
SWEEP_POINTS = 6
"""Sizes per sweep, geometrically spaced from the paper's size to the LQR's failure size."""
FAILURE_TOLERANCE = 0.05
"""Relative precision of the failure size."""
MAX_FAILURE_SIZE = 512.0
"""Doubling stops here: past it the LQR is reported as never failing (``inf``)."""
PULSE_AMPLITUDE = 2.0
"""Largest offset per step, in actuator limits (module docstring)."""
FLAT_TOP = 1.0
"""r(x) == 1: the hybrid applies its linear part G exactly."""


class ImpulsePoint(NamedTuple):
    """One disturbance size for one controller.

    Attributes
    ----------
    size : float
        m: the integral of the offset, in action units times steps.
    held : bool
        The response ends holding the operating point.
    settling_time : int or None
        Steps (2 % band of the peak deviation); None if not settled.
    peak_deviation : float
        Largest ``|e|`` in report units.
    min_relevance : float or None
        Least r(x) along the response (hybrids); None for non-hybrids.
    """

    size: float
    held: bool
    settling_time: int | None
    peak_deviation: float
    min_relevance: float | None

    @property
    def by_construction(self) -> bool:
        """The hybrid never left the flat top, so it equals its LQR along this response."""
        return self.min_relevance is not None and self.min_relevance >= FLAT_TOP


def impulse_offsets(size: float, steps: int, amplitude: float, action_dim: int = 1) -> np.ndarray:
    """Offsets (steps, A) of a disturbance of ``size`` (module docstring): whole steps of
    ``-amplitude``, then the remainder (every action entry)."""
    if not (math.isfinite(size) and size > 0.0):
        raise ValueError(f"size: expected a positive finite number, found {size!r}")
    if not (math.isfinite(amplitude) and amplitude > 0.0):
        raise ValueError(f"amplitude: expected a positive finite number, found {amplitude!r}")
    whole = int(math.floor(size / amplitude))
    remainder = size - whole * amplitude
    if whole + (remainder > 0.0) > steps:
        raise ValueError(
            f"size: expected at most {steps * amplitude:g} ({steps} steps of {amplitude:g}), "
            f"found {size!r}"
        )
    offsets = np.zeros((steps, action_dim))
    offsets[:whole] = -amplitude
    if remainder > 0.0:
        offsets[whole] = -remainder
    return offsets


def pulse_amplitude(system: System) -> float:
    """Largest offset per step: ``PULSE_AMPLITUDE`` times the actuator limit."""
    return PULSE_AMPLITUDE * float(system.action_limit)


def _respond(system: System, controller: Controller, size: float, steps: int) -> ImpulsePoint:
    offsets = impulse_offsets(size, steps, pulse_amplitude(system), system.action_dim)
    trajectory = rollout(system, controller, system.operating_state, steps, offsets)
    deviation = system.main_coordinate(trajectory.states)
    metrics = response_metrics(deviation, None, dt=system.dt, terminated=trajectory.terminated)
    relevance = None if trajectory.relevance is None else float(np.min(trajectory.relevance))
    return ImpulsePoint(
        float(size),
        hold_step(system, trajectory) is not None,
        metrics.settling_time,
        float(np.max(np.abs(deviation))),
        relevance,
    )


def lqr_failure_size(system: System, lqr: Controller, steps: int | None = None) -> float:
    """Smallest size m (relative precision ``FAILURE_TOLERANCE``) at which ``lqr`` no longer
    holds the operating point after the disturbance; ``inf`` if it holds up to
    ``MAX_FAILURE_SIZE`` (or up to the episode length)."""
    steps = system.episode_steps if steps is None else int(steps)
    largest = min(MAX_FAILURE_SIZE, float(steps // 2) * pulse_amplitude(system))
    held, failed = PAPER_SIZE, PAPER_SIZE
    if not _respond(system, lqr, PAPER_SIZE, steps).held:
        return PAPER_SIZE
    while failed <= largest:
        failed = 2.0 * held
        if failed > largest:
            return math.inf
        if not _respond(system, lqr, failed, steps).held:
            break
        held = failed
    while failed - held > FAILURE_TOLERANCE * held:
        middle = 0.5 * (held + failed)
        if _respond(system, lqr, middle, steps).held:
            held = middle
        else:
            failed = middle
    return failed


def sweep_sizes(failure_size: float, points: int = SWEEP_POINTS) -> np.ndarray:
    """Sizes from the paper's 1 to ``failure_size``, geometrically spaced (``points`` of them);
    with an LQR that never fails, up to ``MAX_FAILURE_SIZE``-limited doubling's last size."""
    top = failure_size if math.isfinite(failure_size) else MAX_FAILURE_SIZE
    return np.geomspace(PAPER_SIZE, max(top, PAPER_SIZE), points)


def impulse_sweep(
    system: System,
    controllers: dict[str, Controller],
    sizes: Any,
    steps: int | None = None,
) -> dict[str, list[ImpulsePoint]]:
    """Responses of every controller at every size (:class:`ImpulsePoint` lists by label)."""
    steps = system.episode_steps if steps is None else int(steps)
    return {
        label: [_respond(system, controller, float(size), steps) for size in np.ravel(sizes)]
        for label, controller in controllers.items()
    }
