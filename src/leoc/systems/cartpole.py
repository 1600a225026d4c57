"""Cart-pole swing-up with a continuous force: the classic cart-pole equations of motion.

The equations are those of gymnasium's ``CartPole-v1`` (Barto, Sutton & Anderson 1983, as
corrected by Florian 2007), with theta = 0 upright and a continuous force F on the cart:

.. math::

    \\text{tmp} &= \\frac{F + m_p l \\dot\\theta^2 \\sin\\theta}{m_c + m_p} \\\\
    \\ddot\\theta &= \\frac{g \\sin\\theta - \\cos\\theta \\, \\text{tmp}}
        {l \\left(\\tfrac43 - \\tfrac{m_p \\cos^2\\theta}{m_c + m_p}\\right)} \\\\
    \\ddot x &= \\text{tmp} - \\frac{m_p l \\ddot\\theta \\cos\\theta}{m_c + m_p}

with l the pole's half-length, integrated by explicit Euler (positions first with the old
velocities, then the velocities).

Generalised forces (friction, :mod:`leoc.systems.perturbations`): a force :math:`Q_x` on the
cart adds to the clipped F, and a torque :math:`Q_\\theta` at the pivot adds
:math:`Q_\\theta / (m_p l)` to the numerator of :math:`\\ddot\\theta`: the Lagrange
equations of this model (kinetic energy :math:`\\tfrac12 (m_c + m_p) \\dot x^2 + m_p l
\\cos\\theta \\, \\dot x \\dot\\theta + \\tfrac23 m_p l^2 \\dot\\theta^2`) with the
generalised forces on the right, evaluated at the step's start state. Barto, Sutton & Anderson
(1983) write friction this way, :math:`Q_x = -\\mu_c \\operatorname{sgn}\\dot x` and
:math:`Q_\\theta = -\\mu_p \\dot\\theta`; Florian (2007) makes the cart's Coulomb force
depend on the normal force, which a given :math:`Q_x` does not model.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import ClassVar

import numpy as np
import torch
from torch import Tensor

from leoc.systems.base import PhysicalParams, System, wrap_angle
from leoc.systems.observation import angle_entries, state_entry

REWARD_SCALE = 0.1
THETA_WEIGHT = 5.0
POSITION_WEIGHT = 1.0
FORCE_WEIGHT = 0.005
FOUR_THIRDS = 4.0 / 3.0
START_SPREAD = (0.1, 0.1, math.radians(10.0), 0.1)
# Hold test: 50 steps (1 s) inside the hold band at the end of the episode.
HOLD_MIN_STEPS = 50
# Robustness starts: x +/- 0.2 m, x_dot +/- 0.2 m/s, theta +/- 0.15 rad (8.6 deg),
# theta_dot +/- 0.2 rad/s; the nominal LQR (at dt and at PILCO's 3-step period) recovers from
# every corner.
OPERATING_REGION = (0.2, 0.2, 0.15, 0.2)


@dataclasses.dataclass(frozen=True)
class CartPoleParams(PhysicalParams):
    """Physical constants of the cart-pole (defaults: the paper's experiments).

    Attributes
    ----------
    gravity : float
        g in m/s^2.
    cart_mass : float
        m_c in kg.
    pole_mass : float
        m_p in kg.
    half_length : float
        l, half the pole's length, in m.
    dt : float
        Time step in s.
    max_force : float
        Actuator limit ``|F|`` in N.
    x_limit : float
        The episode ends when ``|x|`` exceeds this, in m.
    """

    MASS_FIELDS: ClassVar[tuple[str, ...]] = ("cart_mass", "pole_mass")

    gravity: float = 9.8
    cart_mass: float = 0.05
    pole_mass: float = 0.005
    half_length: float = 0.5
    dt: float = 0.02
    max_force: float = 2.5
    x_limit: float = 2.4

    @property
    def total_mass(self) -> float:
        """m_c + m_p in kg."""
        return self.cart_mass + self.pole_mass

    @property
    def pole_mass_length(self) -> float:
        """m_p l in kg m."""
        return self.pole_mass * self.half_length


def cartpole_step(
    state: Tensor,
    action: Tensor,
    params: CartPoleParams,
    external: Callable[[Tensor], Tensor] | None = None,
) -> Tensor:
    """One Euler step ``(B, 4), (B, 1) -> (B, 4)`` of ``[x, x_dot, theta, theta_dot]``.

    ``external``: ``state -> (B, 2)``, the generalised forces ``[Q_x (N), Q_theta (N m)]`` on
    the cart and at the pivot (module docstring,
    :meth:`~leoc.systems.base.System.forced_step_fn`); None adds nothing.
    """
    x, x_dot, theta, theta_dot = state.unbind(-1)
    force = torch.clamp(action[..., 0], -params.max_force, params.max_force)
    pole_torque = None
    if external is not None:
        generalised = external(state)
        force, pole_torque = force + generalised[..., 0], generalised[..., 1]
    cos_theta, sin_theta = torch.cos(theta), torch.sin(theta)
    tmp = (force + params.pole_mass_length * theta_dot**2 * sin_theta) / params.total_mass
    numerator = params.gravity * sin_theta - cos_theta * tmp
    if pole_torque is not None:
        numerator = numerator + pole_torque / params.pole_mass_length
    theta_ddot = numerator / (
        params.half_length * (FOUR_THIRDS - params.pole_mass * cos_theta**2 / params.total_mass)
    )
    x_ddot = tmp - params.pole_mass_length * theta_ddot * cos_theta / params.total_mass
    return torch.stack(
        [
            x + params.dt * x_dot,
            x_dot + params.dt * x_ddot,
            theta + params.dt * theta_dot,
            theta_dot + params.dt * theta_ddot,
        ],
        dim=-1,
    )


def cartpole_reward(state: Tensor, action: Tensor, params: CartPoleParams) -> Tensor:
    """Reward ``-0.1 (5 theta^2 + x^2 + 0.005 F^2)``, theta wrapped, F clipped."""
    theta = wrap_angle(state[..., 2])
    force = torch.clamp(action[..., 0], -params.max_force, params.max_force)
    return -REWARD_SCALE * (
        THETA_WEIGHT * theta**2 + POSITION_WEIGHT * state[..., 0] ** 2 + FORCE_WEIGHT * force**2
    )


class CartPole(System):
    """Cart-pole swing-up (state ``[x, x_dot, theta, theta_dot]``,
    observation ``[x, x_dot, cos theta, sin theta, theta_dot]``).

    Operating point: the pole upright at the track centre, at rest, ``u_eq = 0``.
    """

    name = "cartpole"
    params_type = CartPoleParams
    state_names = ("x", "x_dot", "theta", "theta_dot")
    obs_layout = (
        state_entry(0),
        state_entry(1),
        *angle_entries(2),
        state_entry(3),
    )
    main_index = 2
    main_label = "theta [deg]"
    main_in_degrees = True
    settling_band = 1.0
    hold_band = 5.0
    hold_min_steps = HOLD_MIN_STEPS
    operating_region = OPERATING_REGION
    swing_up_centre = (0.0, 0.0, math.pi, 0.0)
    start_spread = START_SPREAD
    default_q = (2.0, 0.3, 2.0, 0.3)
    default_r = (1.0,)
    velocity_indices = (1, 3)
    params: CartPoleParams

    @property
    def out_of_bounds_reward(self) -> float:  # type: ignore[override]
        """The worst reward on the track, per step left (:meth:`System.termination_reward`):
        the pole hanging down (theta = pi) at the track's end with the largest force (the
        reward does not depend on the speeds); about -5.51 with the default parameters."""
        p = self.params
        return -REWARD_SCALE * (
            THETA_WEIGHT * math.pi**2
            + POSITION_WEIGHT * p.x_limit**2
            + FORCE_WEIGHT * p.max_force**2
        )

    @property
    def action_limit(self) -> float:
        return float(self.params.max_force)

    def cost_factor(self) -> np.ndarray:
        """PILCO's cost distance: the pole tip to its upright position over the track centre,
        ``(x + L sin)^2 + L^2 (cos - 1)^2`` with L the pole length (observation
        ``[x, x_dot, cos, sin, theta_dot]``)."""
        length = 2.0 * self.params.half_length
        return np.array([[1.0, 0.0, 0.0, length, 0.0], [0.0, 0.0, length, 0.0, 0.0]])

    def step_fn(self, state: Tensor, action: Tensor) -> Tensor:
        return cartpole_step(state, action, self.params)

    def forced_step_fn(
        self, state: Tensor, action: Tensor, force: Callable[[Tensor], Tensor]
    ) -> Tensor:
        return cartpole_step(state, action, self.params, force)

    def reward_fn(self, state: Tensor, action: Tensor) -> Tensor:
        return cartpole_reward(state, action, self.params)

    def out_of_bounds(self, state: Tensor) -> Tensor:
        return torch.abs(state[..., 0]) > self.params.x_limit

    def continuous_model(self) -> tuple[np.ndarray, np.ndarray]:
        """The paper's appendix-B model with I = m_p l^2 / 3 (the rod about its centre, which is
        what the 4/3 of the equations of motion encodes), M = m_c, m = m_p, in our sign
        convention (theta and F as in the equations above; the paper's theta runs the other
        way, which flips the signs of the coupling terms):

        with D = I (M + m) + M m l^2,
        A[1, 2] = -m^2 l^2 g / D, A[3, 2] = m l g (M + m) / D,
        B[1] = (I + m l^2) / D, B[3] = -m l / D.
        """
        p = self.params
        big_m, small_m, half = p.cart_mass, p.pole_mass, p.half_length
        inertia = small_m * half**2 / 3.0
        denominator = inertia * (big_m + small_m) + big_m * small_m * half**2
        a_matrix = np.zeros((4, 4))
        a_matrix[0, 1] = 1.0
        a_matrix[2, 3] = 1.0
        a_matrix[1, 2] = -(small_m**2) * half**2 * p.gravity / denominator
        a_matrix[3, 2] = small_m * half * p.gravity * (big_m + small_m) / denominator
        b_matrix = np.zeros((4, 1))
        b_matrix[1, 0] = (inertia + small_m * half**2) / denominator
        b_matrix[3, 0] = -small_m * half / denominator
        return a_matrix, b_matrix
