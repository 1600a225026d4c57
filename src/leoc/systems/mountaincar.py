"""Mountain car that must reach and stay on the hilltop.

The car of mass m moves along x under a force F and the slope of the hill
``h(x) = 1.35 cos x + 1.65`` (hilltop at x = 0, valley at x = -pi):

.. math::

    \\ddot x = \\frac{F}{m} - g\\, h'(x) = \\frac{F}{m} + 1.35\\, g \\sin x

integrated by semi-implicit Euler (``x_dot' = x_dot + dt x_ddot``, ``x' = x + dt x_dot'``).
A generalised force Q along the track (friction, :mod:`leoc.systems.perturbations`) adds to the
clipped F: ``(F + Q) / m``, Q evaluated at the step's start state.
The hilltop is an unstable equilibrium with ``u_eq = 0``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import ClassVar

import numpy as np
import torch
from torch import Tensor

from leoc.systems.base import PhysicalParams, System
from leoc.systems.observation import state_entry

REWARD_SCALE = 0.1
POSITION_WEIGHT = 5.0
SPEED_WEIGHT = 1.0
FORCE_WEIGHT = 0.005
START_SPREAD = (math.radians(10.0), 0.1)
# Hold test: 50 steps (1 s) inside the hold band at the end of the episode.
HOLD_MIN_STEPS = 50
# Robustness starts: x +/- 0.1 m, x_dot +/- 0.1 m/s around the hilltop; the nominal LQR (at dt
# and at PILCO's 3-step period) recovers from every corner.
OPERATING_REGION = (0.1, 0.1)
# The track of the original experiments, [-3.6, 2.2] in a frame whose hilltop is at pi / 2.
TRACK_LOW = -3.6 - math.pi / 2.0
TRACK_HIGH = 2.2 - math.pi / 2.0


@dataclasses.dataclass(frozen=True)
class MountainCarParams(PhysicalParams):
    """Physical constants of the mountain car (defaults: the paper's experiments).

    Attributes
    ----------
    gravity : float
        g in m/s^2.
    mass : float
        Car mass in kg.
    hill_amplitude : float
        Amplitude of the hill profile h(x) = amplitude cos x + offset, in m.
    hill_offset : float
        Offset of the hill profile in m (does not enter the dynamics).
    dt : float
        Time step in s.
    max_force : float
        Actuator limit ``|F|`` in N.
    """

    MASS_FIELDS: ClassVar[tuple[str, ...]] = ("mass",)

    gravity: float = 9.8
    mass: float = 0.1
    hill_amplitude: float = 1.35
    hill_offset: float = 1.65
    dt: float = 0.02
    max_force: float = 3.0


def hill_height(x: Tensor, params: MountainCarParams) -> Tensor:
    """h(x) = amplitude cos x + offset, in m."""
    return params.hill_amplitude * torch.cos(x) + params.hill_offset


def mountaincar_step(
    state: Tensor,
    action: Tensor,
    params: MountainCarParams,
    external: Callable[[Tensor], Tensor] | None = None,
) -> Tensor:
    """One semi-implicit Euler step ``(B, 2), (B, 1) -> (B, 2)`` of ``[x, x_dot]``.

    ``external``: ``state -> (B, 1)``, a generalised force along the track in N added to the
    clipped force (:meth:`~leoc.systems.base.System.forced_step_fn`); None adds nothing.
    """
    x, x_dot = state[..., 0], state[..., 1]
    force = torch.clamp(action[..., 0], -params.max_force, params.max_force)
    if external is not None:
        force = force + external(state)[..., 0]
    slope = -params.hill_amplitude * torch.sin(x)  # h'(x)
    x_ddot = force / params.mass - params.gravity * slope
    new_x_dot = x_dot + params.dt * x_ddot
    return torch.stack([x + params.dt * new_x_dot, new_x_dot], dim=-1)


def mountaincar_reward(state: Tensor, action: Tensor, params: MountainCarParams) -> Tensor:
    """Reward ``-0.1 (5 x^2 + x_dot^2 + 0.005 F^2)`` with F clipped."""
    force = torch.clamp(action[..., 0], -params.max_force, params.max_force)
    return -REWARD_SCALE * (
        POSITION_WEIGHT * state[..., 0] ** 2
        + SPEED_WEIGHT * state[..., 1] ** 2
        + FORCE_WEIGHT * force**2
    )


class MountainCar(System):
    """Mountain car on the hilltop (state = observation = ``[x, x_dot]``)."""

    name = "mountaincar"
    params_type = MountainCarParams
    state_names = ("x", "x_dot")
    obs_layout = (state_entry(0), state_entry(1))
    main_index = 0
    main_label = "x [m]"
    main_in_degrees = False
    settling_band = 0.001
    hold_band = 0.05
    hold_min_steps = HOLD_MIN_STEPS
    operating_region = OPERATING_REGION
    swing_up_centre = (-math.pi, 0.0)
    start_spread = START_SPREAD
    default_q = (2.0, 0.3)
    default_r = (1.0,)
    velocity_indices = (1,)
    params: MountainCarParams

    @property
    def out_of_bounds_reward(self) -> float:  # type: ignore[override]
        """The worst reward at rest on the track, per step left
        (:meth:`System.termination_reward`): the car standing at the track's far end with the
        largest force; about -13.4 with the default parameters. (Speed makes the reward worse
        still, but standing at the bottom of the valley, about -4.93, is already far better.)"""
        far_end = max(abs(TRACK_LOW), abs(TRACK_HIGH))
        return -REWARD_SCALE * (
            POSITION_WEIGHT * far_end**2 + FORCE_WEIGHT * self.params.max_force**2
        )

    @property
    def action_limit(self) -> float:
        return float(self.params.max_force)

    def step_fn(self, state: Tensor, action: Tensor) -> Tensor:
        return mountaincar_step(state, action, self.params)

    def forced_step_fn(
        self, state: Tensor, action: Tensor, force: Callable[[Tensor], Tensor]
    ) -> Tensor:
        return mountaincar_step(state, action, self.params, force)

    def reward_fn(self, state: Tensor, action: Tensor) -> Tensor:
        return mountaincar_reward(state, action, self.params)

    def out_of_bounds(self, state: Tensor) -> Tensor:
        return (state[..., 0] < TRACK_LOW) | (state[..., 0] > TRACK_HIGH)

    def continuous_model(self) -> tuple[np.ndarray, np.ndarray]:
        """Analytic linearisation about the hilltop: A = [[0, 1], [a g, 0]], B = [[0], [1/m]]
        with a the hill amplitude (h''(0) = -a). The paper's appendix B writes g and -1/M: it
        drops the curvature factor a and uses the opposite sign for the force.
        """
        p = self.params
        a_matrix = np.array([[0.0, 1.0], [p.hill_amplitude * p.gravity, 0.0]])
        b_matrix = np.array([[0.0], [1.0 / p.mass]])
        return a_matrix, b_matrix
