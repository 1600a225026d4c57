r"""Acrobot swing-up and balance: a two-link pendulum with torque at the elbow only.

Built only through the public ``System`` protocol (:mod:`leoc.systems.base`,
:mod:`leoc.systems.observation`); registered as ``acrobot`` (``leoc/Acrobot-v0``).

Equations of motion: the "book" dynamics of Sutton & Barto (1998, sec. 11.3), as in
gymnasium's ``Acrobot-v1``, with both angles measured so that the operating point is upright.
:math:`\theta_1` is the angle of link 1 from the upright vertical, :math:`\theta_2` the angle of
link 2 relative to link 1 (both anticlockwise); the torque :math:`\tau` acts at the elbow
(between the links) only. With :math:`m_i` the masses, :math:`l_1` the length of link 1,
:math:`l_{ci}` the distances from the joints to the centres of mass, :math:`I_i` the moments of
inertia about the centres of mass and g gravity:

.. math::

    d_1 &= m_1 l_{c1}^2 + m_2 (l_1^2 + l_{c2}^2 + 2 l_1 l_{c2} \cos\theta_2) + I_1 + I_2 \\
    d_2 &= m_2 (l_{c2}^2 + l_1 l_{c2} \cos\theta_2) + I_2 \\
    \phi_2 &= -m_2 l_{c2} g \sin(\theta_1 + \theta_2) \\
    \phi_1 &= -m_2 l_1 l_{c2} \dot\theta_2^2 \sin\theta_2
              - 2 m_2 l_1 l_{c2} \dot\theta_1 \dot\theta_2 \sin\theta_2
              - (m_1 l_{c1} + m_2 l_1) g \sin\theta_1 + \phi_2 \\
    \ddot\theta_2 &= \frac{\tau + \tfrac{d_2}{d_1} \phi_1
              - m_2 l_1 l_{c2} \dot\theta_1^2 \sin\theta_2 - \phi_2}
              {m_2 l_{c2}^2 + I_2 - d_2^2 / d_1} \\
    \ddot\theta_1 &= -(d_2 \ddot\theta_2 + \phi_1) / d_1

(the book's gravity terms :math:`\cos(\theta - \pi/2)` become :math:`-\sin\theta` when the
angle is measured from upright instead of hanging). They are the Lagrange equations of the
energy

.. math::

    E = \tfrac12 \dot q^\top M(\theta_2) \dot q + g (m_1 l_{c1} + m_2 l_1) \cos\theta_1
        + g m_2 l_{c2} \cos(\theta_1 + \theta_2), \qquad
    M = \begin{pmatrix} d_1 & d_2 \\ d_2 & m_2 l_{c2}^2 + I_2 \end{pmatrix},

conserved without torque (:func:`acrobot_energy`; the tests check it). One step integrates
them by classic fourth-order Runge-Kutta over ``dt`` with the torque held, then clips the
speeds to gymnasium's limits (:math:`4\pi` and :math:`9\pi` rad/s). Generalised forces
:math:`Q_1` at the shoulder and :math:`Q_2` at the elbow (friction,
:mod:`leoc.systems.perturbations`) enter as :math:`\phi_1 \to \phi_1 - Q_1` and
:math:`\tau \to \tau + Q_2`, i.e. :math:`M \ddot q + \dots = (Q_1, \tau + Q_2)`,
evaluated at every Runge-Kutta stage; then :math:`dE/dt = \tau \dot\theta_2 + Q_1
\dot\theta_1 + Q_2 \dot\theta_2`.

Parameters: gymnasium's ``Acrobot-v1`` (unit masses and lengths, centres of mass at mid-link,
unit moments of inertia, g = 9.8); the continuous torque limit (5 N m), ``dt`` (0.05 s instead of
gymnasium's 0.2 s, so that a 200-step episode lasts 10 s and the LQR acts at 20 Hz) and the
reward are ours.

References
----------
R. S. Sutton and A. G. Barto, "Reinforcement Learning: An Introduction", MIT Press 1998,
sec. 11.3 (the acrobot). M. W. Spong, "The swing up control problem for the Acrobot",
IEEE Control Systems Magazine 15(1), 1995.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import ClassVar

import numpy as np
import torch
from torch import Tensor

from leoc.systems.base import DTYPE, PhysicalParams, System, wrap_angle
from leoc.systems.observation import angle_entries, state_entry

ANGLE_WEIGHT = 1.0
SPEED_WEIGHT = 0.1
TORQUE_WEIGHT = 0.001
START_ANGLE_SPREAD = math.radians(10.0)
START_SPEED_SPREAD = 0.1
RK4_WEIGHTS = (1.0, 2.0, 2.0, 1.0)
# Hold test: 50 steps (2.5 s) with link 1 within the hold band at the end of the episode.
HOLD_MIN_STEPS = 50
# Robustness starts: both angles +/- 0.02 rad (1.1 deg), both speeds +/- 0.04 rad/s. The nominal
# LQR recovers from every corner of this box (tests/test_acrobot.py checks it) but not from
# 0.03 / 0.06: its gains (|K| ~ 170 N m/rad on theta1) saturate the 5 N m elbow within 0.03 rad,
# the acrobot's weak control authority at the top (gymnasium's is 1 N m; 10 or 20 N m only
# moves the edge to 0.03-0.05 rad).
OPERATING_REGION = (0.02, 0.02, 0.04, 0.04)


@dataclasses.dataclass(frozen=True)
class AcrobotParams(PhysicalParams):
    """Physical constants of the acrobot (defaults: gymnasium ``Acrobot-v1``, our torque/dt).

    Attributes
    ----------
    gravity : float
        g in m/s^2.
    link_mass_1, link_mass_2 : float
        m_1, m_2 in kg.
    link_length_1 : float
        l_1 in m (link 2's length only enters through l_c2 and I_2).
    link_com_1, link_com_2 : float
        l_c1, l_c2: joint to centre of mass, in m.
    link_moi_1, link_moi_2 : float
        I_1, I_2: moments of inertia about the centres of mass, in kg m^2.
    dt : float
        Time step in s.
    max_torque : float
        Elbow torque limit in N m.
    max_speed_1, max_speed_2 : float
        Speed limits of the two joints in rad/s.
    """

    MASS_FIELDS: ClassVar[tuple[str, ...]] = ("link_mass_1", "link_mass_2")

    gravity: float = 9.8
    link_mass_1: float = 1.0
    link_mass_2: float = 1.0
    link_length_1: float = 1.0
    link_com_1: float = 0.5
    link_com_2: float = 0.5
    link_moi_1: float = 1.0
    link_moi_2: float = 1.0
    dt: float = 0.05
    max_torque: float = 5.0
    max_speed_1: float = 4.0 * math.pi
    max_speed_2: float = 9.0 * math.pi


def _inertia(theta2: Tensor, p: AcrobotParams) -> tuple[float, Tensor, Tensor, float]:
    """The mass-matrix entries ``(m2 l1 lc2, d1, d2, d3)`` of the book dynamics (module
    docstring): ``M = [[d1, d2], [d2, d3]]``, shared by the dynamics and the energy."""
    coupling = p.link_mass_2 * p.link_length_1 * p.link_com_2  # m2 l1 lc2
    d1 = (
        p.link_mass_1 * p.link_com_1**2
        + p.link_mass_2 * (p.link_length_1**2 + p.link_com_2**2)
        + 2.0 * coupling * torch.cos(theta2)
        + p.link_moi_1
        + p.link_moi_2
    )
    d2 = p.link_mass_2 * p.link_com_2**2 + coupling * torch.cos(theta2) + p.link_moi_2
    d3 = p.link_mass_2 * p.link_com_2**2 + p.link_moi_2
    return coupling, d1, d2, d3


def acrobot_derivative(
    state: Tensor,
    torque: Tensor,
    params: AcrobotParams,
    external: Callable[[Tensor], Tensor] | None = None,
) -> Tensor:
    """Time derivative ``(B, 4)`` of ``[theta1, theta2, theta1_dot, theta2_dot]`` (module
    docstring), for an elbow torque ``(B,)`` and optional generalised torques
    ``external(state)`` ``(B, 2)`` at the shoulder and the elbow (N m)."""
    p = params
    theta1, theta2, theta1_dot, theta2_dot = state.unbind(-1)
    coupling, d1, d2, d3 = _inertia(theta2, p)
    phi2 = -p.link_mass_2 * p.link_com_2 * p.gravity * torch.sin(theta1 + theta2)
    phi1 = (
        -coupling * theta2_dot**2 * torch.sin(theta2)
        - 2.0 * coupling * theta1_dot * theta2_dot * torch.sin(theta2)
        - (p.link_mass_1 * p.link_com_1 + p.link_mass_2 * p.link_length_1)
        * p.gravity
        * torch.sin(theta1)
        + phi2
    )
    if external is not None:
        generalised = external(state)
        phi1, torque = phi1 - generalised[..., 0], torque + generalised[..., 1]
    theta2_ddot = (
        torque + d2 / d1 * phi1 - coupling * theta1_dot**2 * torch.sin(theta2) - phi2
    ) / (d3 - d2**2 / d1)
    theta1_ddot = -(d2 * theta2_ddot + phi1) / d1
    return torch.stack([theta1_dot, theta2_dot, theta1_ddot, theta2_ddot], dim=-1)


def acrobot_step(
    state: Tensor,
    action: Tensor,
    params: AcrobotParams,
    external: Callable[[Tensor], Tensor] | None = None,
) -> Tensor:
    """One step ``(B, 4), (B, 1) -> (B, 4)``: RK4 over ``dt`` with the clipped torque held,
    then the speeds clipped to their limits. ``external``: generalised torques
    (:func:`acrobot_derivative`), evaluated at every stage; None adds nothing."""
    torque = torch.clamp(action[..., 0], -params.max_torque, params.max_torque)
    dt = params.dt
    k1 = acrobot_derivative(state, torque, params, external)
    k2 = acrobot_derivative(state + 0.5 * dt * k1, torque, params, external)
    k3 = acrobot_derivative(state + 0.5 * dt * k2, torque, params, external)
    k4 = acrobot_derivative(state + dt * k3, torque, params, external)
    slopes = (k1, k2, k3, k4)
    increment = sum(w * k for w, k in zip(RK4_WEIGHTS, slopes, strict=True)) / sum(RK4_WEIGHTS)
    following = state + dt * increment
    speed1 = torch.clamp(following[..., 2], -params.max_speed_1, params.max_speed_1)
    speed2 = torch.clamp(following[..., 3], -params.max_speed_2, params.max_speed_2)
    return torch.stack([following[..., 0], following[..., 1], speed1, speed2], dim=-1)


def acrobot_energy(state: Tensor, params: AcrobotParams) -> Tensor:
    """Total energy ``(B,)`` in J (module docstring), zero-velocity potential 0 at horizontal."""
    p = params
    theta1, theta2, theta1_dot, theta2_dot = state.unbind(-1)
    _, d1, d2, d3 = _inertia(theta2, p)
    kinetic = 0.5 * (d1 * theta1_dot**2 + 2.0 * d2 * theta1_dot * theta2_dot + d3 * theta2_dot**2)
    potential = p.gravity * (
        (p.link_mass_1 * p.link_com_1 + p.link_mass_2 * p.link_length_1) * torch.cos(theta1)
        + p.link_mass_2 * p.link_com_2 * torch.cos(theta1 + theta2)
    )
    return kinetic + potential


def acrobot_reward(state: Tensor, action: Tensor, params: AcrobotParams) -> Tensor:
    """Reward ``-(theta1^2 + theta2^2 + 0.1 (theta1_dot^2 + theta2_dot^2) + 0.001 tau^2)``
    with both angles wrapped and the torque clipped."""
    angles = wrap_angle(state[..., 0]) ** 2 + wrap_angle(state[..., 1]) ** 2
    speeds = state[..., 2] ** 2 + state[..., 3] ** 2
    torque = torch.clamp(action[..., 0], -params.max_torque, params.max_torque)
    return -(ANGLE_WEIGHT * angles + SPEED_WEIGHT * speeds + TORQUE_WEIGHT * torque**2)


class Acrobot(System):
    """Acrobot swing-up (state ``[theta1, theta2, theta1_dot, theta2_dot]``, observation
    ``[cos theta1, sin theta1, cos theta2, sin theta2, theta1_dot, theta2_dot]`` as gymnasium's
    ``Acrobot-v1``).

    ==============  ===========================================================
    Action          elbow torque tau in N m, ``|tau|`` <= 5 (clipped)
    Dynamics        module docstring; RK4, dt = 0.05 s
    Reward          :func:`acrobot_reward`
    Start           swing_up: both links hanging, theta1 = pi +/- 10 deg,
                    theta2 = 0 +/- 10 deg, speeds 0 +/- 0.1 (uniform);
                    operating_point: [0, 0, 0, 0] (+ offset)
    Termination     none; truncation after 200 steps
    Hold test       link 1 within 5 deg of upright for the last 50 steps
    ==============  ===========================================================

    The operating point is both links upright at rest, ``u_eq = 0``.
    """

    name = "acrobot"
    params_type = AcrobotParams
    state_names = ("theta1", "theta2", "theta1_dot", "theta2_dot")
    obs_layout = (*angle_entries(0), *angle_entries(1), state_entry(2), state_entry(3))
    main_index = 0
    main_label = "theta1 [deg]"
    main_in_degrees = True
    settling_band = 1.0
    hold_band = 5.0
    hold_min_steps = HOLD_MIN_STEPS
    operating_region = OPERATING_REGION
    swing_up_centre = (math.pi, 0.0, 0.0, 0.0)
    start_spread = (START_ANGLE_SPREAD, START_ANGLE_SPREAD, START_SPEED_SPREAD, START_SPEED_SPREAD)
    default_q = (10.0, 10.0, 1.0, 1.0)
    default_r = (1.0,)
    velocity_indices = (2, 3)

    params: AcrobotParams

    @property
    def action_limit(self) -> float:
        return float(self.params.max_torque)

    def cost_factor(self) -> np.ndarray:
        """PILCO's cost distance: ``l1^2 |(cos1, sin1) - (1, 0)|^2 + l2^2 |(cos2, sin2) -
        (1, 0)|^2`` with l2 = 2 l_c2 (each link's direction to upright, weighted by length)."""
        factor = np.zeros((4, 6))
        factor[0, 0] = factor[1, 1] = self.params.link_length_1
        factor[2, 2] = factor[3, 3] = 2.0 * self.params.link_com_2
        return factor

    def step_fn(self, state: Tensor, action: Tensor) -> Tensor:
        return acrobot_step(state, action, self.params)

    def forced_step_fn(
        self, state: Tensor, action: Tensor, force: Callable[[Tensor], Tensor]
    ) -> Tensor:
        return acrobot_step(state, action, self.params, force)

    def reward_fn(self, state: Tensor, action: Tensor) -> Tensor:
        return acrobot_reward(state, action, self.params)

    def continuous_model(self) -> tuple[np.ndarray, np.ndarray]:
        """``A = d f / d x``, ``B = d f / d tau`` of the vector field at the upright rest state
        (autodiff of :func:`acrobot_derivative`; no separate analytic model is published in
        the paper for the acrobot)."""
        state = torch.zeros(4, dtype=DTYPE)
        torque = torch.zeros((), dtype=DTYPE)
        a_matrix, b_matrix = torch.autograd.functional.jacobian(
            lambda x, u: acrobot_derivative(x, u, self.params), (state, torque)
        )
        return a_matrix.numpy(), b_matrix.numpy().reshape(4, 1)
