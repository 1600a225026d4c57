"""Numbers typed in from the paper, to set beside ours in reports.

Source: Zhang, N. and Capel, N. (2021), "LEOC: A Principled Method in Integrating Reinforcement
Learning and Classical Control Theory", L4DC, appendix D ("Impulse response metrics"). Units as
the paper gives them: degrees for Pendulum and CartPole, position for MountainCar; settling time
in time steps. ``None`` is the paper's "-" (no overshoot reported).

How the paper's definitions differ from ours is not stated in the paper; from its numbers:
its settling band is not given (its MountainCar settling times of ~201 steps exceed a 200-step
episode, so its runs or its band differ from ours), and its impulse is applied in the frame of
its own sign conventions. Our definitions are in :mod:`leoc.evaluation.metrics`.
"""

from __future__ import annotations

from typing import NamedTuple


class PaperMetrics(NamedTuple):
    """Mean and std over seeds of one row of appendix D."""

    steady_state_error: tuple[float, float]
    overshoot: tuple[float, float] | None
    settling_time: tuple[float, float]


PAPER_IMPULSE_METRICS: dict[str, dict[str, PaperMetrics]] = {
    "pendulum": {
        "ddpg_baseline": PaperMetrics((-1.79, 0.66), None, (29.33, 16.13)),
        "ddpg_hybrid": PaperMetrics((-2.92e-13, 0.0), (0.44, 0.0), (26.00, 0.0)),
        "pilco_baseline": PaperMetrics((0.33, 6.05), (5.26, 3.33), (49.33, 21.23)),
        "pilco_hybrid": PaperMetrics((-3.13e-13, -2.33e-16), (0.47, 2.09e-3), (26.00, 0.0)),
        "linear": PaperMetrics((-2.95e-13, 0.0), (0.45, 0.0), (26.00, 0.0)),
    },
    "cartpole": {
        "ddpg_baseline": PaperMetrics((9.97e-4, 3.79e-3), (2.88, 0.86), (282.25, 75.40)),
        "ddpg_hybrid": PaperMetrics((4.79e-6, 7.46e-7), (0.67, 7.46e-7), (121.00, 5.02)),
        "pilco_baseline": PaperMetrics((2.63e-2, 1.41e-2), (1.34, 0.15), (262.67, 27.81)),
        "pilco_hybrid": PaperMetrics((7.16e-6, 6.69e-7), (0.93, 2.97e-2), (138.33, 2.62)),
        "linear": PaperMetrics((4.17e-6, 0.0), (0.67, 0.0), (117.00, 0.0)),
    },
    "mountaincar": {
        "ddpg_baseline": PaperMetrics((0.24, 1.64e-2), None, (33.67, 1.25)),
        "ddpg_hybrid": PaperMetrics((-2.11e-7, 1.23e-8), (6.39e-3, 4.11e-4), (201.50, 0.73)),
        "pilco_baseline": PaperMetrics((-1.50e-2, 1.27e-3), (2.07e-2, 6.69e-3), (147.00, 76.37)),
        "pilco_hybrid": PaperMetrics((-2.23e-7, 1.25e-9), (6.73e-3, 3.46e-5), (201.00, 0.50)),
        "linear": PaperMetrics((-2.12e-7, 0.0), (6.43e-3, 0.0), (201.00, 0.0)),
    },
}
