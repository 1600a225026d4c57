"""Pendulum swing-up: the dynamics of gymnasium's ``Pendulum-v1`` as a pure torch function.

Equations of motion (a uniform rod of mass m and length l about its end, theta = 0 upright,
theta positive anticlockwise, torque u positive in the direction of increasing theta):

.. math::

    \\ddot\\theta = \\frac{3 g}{2 l} \\sin\\theta + \\frac{3}{m l^2} u

integrated by semi-implicit Euler with the speed clipped to ``max_speed``:
``theta_dot' = clip(theta_dot + dt * theta_ddot)``, ``theta' = theta + dt * theta_dot'``.
A generalised torque Q at the pivot (friction, :mod:`leoc.systems.perturbations`) adds to the
clipped u: ``3 / (m l^2) (u + Q)``, Q evaluated at the step's start state.
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

THETA_WEIGHT = 1.0
THETA_DOT_WEIGHT = 0.1
TORQUE_WEIGHT = 0.001
START_ANGLE_SPREAD = math.radians(10.0)
START_SPEED_SPREAD = 0.1
# Hold test: 50 steps (2.5 s) inside the hold band at the end of the episode.
HOLD_MIN_STEPS = 50
# Robustness starts: theta +/- 0.2 rad (11.5 deg), theta_dot +/- 0.3 rad/s. The nominal LQR (at
# dt, at PILCO's 2-step period and at 3 steps) recovers from every corner of this box. Holding
# theta = 0.2 rad takes m g l sin(theta) / 2 = 1.0 N m of the 2 N m limit, so at 2x g or mass
# the corners are at the actuator's reach and beyond it any controller must fail: a sweep that
# can fail.
OPERATING_REGION = (0.2, 0.3)


@dataclasses.dataclass(frozen=True)
class PendulumParams(PhysicalParams):
    """Physical constants of the pendulum (defaults: gymnasium ``Pendulum-v1``).

    Attributes
    ----------
    gravity : float
        g in m/s^2.
    mass : float
        Rod mass m in kg.
    length : float
        Rod length l in m (the pivot is at one end).
    dt : float
        Time step in s.
    max_torque : float
        Actuator limit in N m.
    max_speed : float
        Angular speed limit in rad/s.
    """

    MASS_FIELDS: ClassVar[tuple[str, ...]] = ("mass",)

    gravity: float = 10.0
    mass: float = 1.0
    length: float = 1.0
    dt: float = 0.05
    max_torque: float = 2.0
    max_speed: float = 8.0

    @property
    def inertia(self) -> float:
        """Moment of inertia about the pivot, m l^2 / 3, in kg m^2."""
        return self.mass * self.length**2 / 3.0


def pendulum_step(
    state: Tensor,
    action: Tensor,
    params: PendulumParams,
    legacy: bool = False,
    force: Callable[[Tensor], Tensor] | None = None,
) -> Tensor:
    """One step ``(B, 2), (B, 1) -> (B, 2)`` of state ``[theta, theta_dot]``.

    ``legacy``: gym 0.17's ``Pendulum-v0`` (the authors' base class, nrjc/LEOC
    ``dao/envs/pendulum_env.py``), which writes the gravity term ``-sin(theta + pi)`` (in floating
    point not exactly ``sin(theta)``: ``pi`` is rounded, a bias of about 1.2e-16 that sets the
    last digits of a decayed response) and clips the speed after the position update.
    ``force``: ``state -> (B, 1)``, a generalised torque at the pivot in N m added to the
    clipped torque (:meth:`~leoc.systems.base.System.forced_step_fn`); None adds nothing.
    """
    theta, theta_dot = state[..., 0], state[..., 1]
    torque = torch.clamp(action[..., 0], -params.max_torque, params.max_torque)
    if force is not None:
        torque = torque + force(state)[..., 0]
    gravity_term = -torch.sin(theta + math.pi) if legacy else torch.sin(theta)
    theta_ddot = (
        3.0 * params.gravity / (2.0 * params.length) * gravity_term
        + 3.0 / (params.mass * params.length**2) * torque
    )
    new_theta_dot = theta_dot + theta_ddot * params.dt
    if legacy:
        new_theta = theta + new_theta_dot * params.dt
        new_theta_dot = torch.clamp(new_theta_dot, -params.max_speed, params.max_speed)
    else:
        new_theta_dot = torch.clamp(new_theta_dot, -params.max_speed, params.max_speed)
        new_theta = theta + new_theta_dot * params.dt
    return torch.stack([new_theta, new_theta_dot], dim=-1)


def pendulum_reward(state: Tensor, action: Tensor, params: PendulumParams) -> Tensor:
    """Reward ``-(theta^2 + 0.1 theta_dot^2 + 0.001 u^2)`` with theta wrapped and u clipped."""
    theta = wrap_angle(state[..., 0])
    torque = torch.clamp(action[..., 0], -params.max_torque, params.max_torque)
    return -(
        THETA_WEIGHT * theta**2 + THETA_DOT_WEIGHT * state[..., 1] ** 2 + TORQUE_WEIGHT * torque**2
    )


class Pendulum(System):
    """Pendulum swing-up (state ``[theta, theta_dot]``, observation ``[cos, sin, theta_dot]``).

    The operating point is the upright position ``theta = 0, theta_dot = 0`` with ``u_eq = 0``.
    """

    name = "pendulum"
    params_type = PendulumParams
    state_names = ("theta", "theta_dot")
    obs_layout = (*angle_entries(0), state_entry(1))
    main_index = 0
    main_label = "theta [deg]"
    main_in_degrees = True
    settling_band = 1.0
    hold_band = 5.0
    hold_min_steps = HOLD_MIN_STEPS
    operating_region = OPERATING_REGION
    swing_up_centre = (math.pi, 0.0)
    start_spread = (START_ANGLE_SPREAD, START_SPEED_SPREAD)
    default_q = (2.0, 2.0)
    default_r = (1.0,)
    velocity_indices = (1,)

    params: PendulumParams

    @property
    def action_limit(self) -> float:
        return float(self.params.max_torque)

    def cost_factor(self) -> np.ndarray:
        """PILCO's cost distance: the rod tip to the upright tip,
        ``l^2 ((cos - 1)^2 + sin^2)`` (observation ``[cos, sin, theta_dot]``)."""
        length = self.params.length
        return np.array([[length, 0.0, 0.0], [0.0, length, 0.0]])

    def step_fn(self, state: Tensor, action: Tensor) -> Tensor:
        return pendulum_step(state, action, self.params, self.rules.legacy_integrator)

    def forced_step_fn(
        self, state: Tensor, action: Tensor, force: Callable[[Tensor], Tensor]
    ) -> Tensor:
        return pendulum_step(state, action, self.params, self.rules.legacy_integrator, force)

    def reward_fn(self, state: Tensor, action: Tensor) -> Tensor:
        return pendulum_reward(state, action, self.params)

    def continuous_model(self) -> tuple[np.ndarray, np.ndarray]:
        """The paper's appendix-B model with l_c = l / 2 and I = m l_c^2 / 3 (rod about its
        centre), in our sign convention (positive torque raises theta_ddot; the paper writes
        the input with the opposite sign):

        A = [[0, 1], [m l_c g / (m l_c^2 + I), 0]],  B = [[0], [1 / (m l_c^2 + I)]].
        """
        p = self.params
        centre = p.length / 2.0
        inertia_centre = p.mass * centre**2 / 3.0
        pivot_inertia = p.mass * centre**2 + inertia_centre
        a_matrix = np.array([[0.0, 1.0], [p.mass * centre * p.gravity / pivot_inertia, 0.0]])
        b_matrix = np.array([[0.0], [1.0 / pivot_inertia]])
        return a_matrix, b_matrix
