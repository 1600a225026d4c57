r"""A cart on a rail with a viscous damper and an unstable spring: a user's system in one file.

This file is the worked example of ``docs/user_guide/custom_system.md`` (a test runs it, so it
cannot rot).

Equations of motion: a cart of mass m on a rail, pushed by a force F, slowed by a damper of
coefficient c and pushed away from the centre by a negative-stiffness spring k (a magnet, an
inverted pendulum's linearisation): the origin is an unstable equilibrium, as LEOC expects.

.. math::

    m \ddot x = F - c \dot x + k x

integrated by semi-implicit Euler: ``x_dot' = x_dot + dt x_ddot``, ``x' = x + dt x_dot'``.
Leaving ``|x| <= x_limit`` ends the episode.

Run it: ``python docs/examples/damped_cart.py`` (registers the system, prints its LQR, trains a
TD3 hybrid for a few hundred steps and compares its impulse response with the LQR's).
"""

from __future__ import annotations

import dataclasses
import tempfile
from typing import ClassVar

import numpy as np
import torch
from torch import Tensor

from leoc.systems import PhysicalParams, System, register_system, state_entry, system_names

POSITION_WEIGHT = 1.0
SPEED_WEIGHT = 0.1
FORCE_WEIGHT = 0.001
# Reward per step left when an episode leaves the rail (System.termination_reward): below every
# reward on the rail, so that driving off early never pays.
OUT_OF_BOUNDS_REWARD = -100.0


@dataclasses.dataclass(frozen=True)
class DampedCartParams(PhysicalParams):
    """Physical constants (every field positive; ``mass=2.0`` scales ``MASS_FIELDS``).

    Attributes
    ----------
    mass : float
        m in kg.
    damping : float
        c in N s/m.
    stiffness : float
        k in N/m (pushing away from the centre).
    dt : float
        Time step in s.
    max_force : float
        Actuator limit in N.
    x_limit : float
        Half-length of the rail in m.
    """

    MASS_FIELDS: ClassVar[tuple[str, ...]] = ("mass",)

    mass: float = 1.0
    damping: float = 0.5
    stiffness: float = 2.0
    dt: float = 0.05
    max_force: float = 3.0
    x_limit: float = 3.0


def damped_cart_step(state: Tensor, action: Tensor, params: DampedCartParams) -> Tensor:
    """One step ``(B, 2), (B, 1) -> (B, 2)`` of ``[x, x_dot]`` (module docstring)."""
    x, x_dot = state[..., 0], state[..., 1]
    force = torch.clamp(action[..., 0], -params.max_force, params.max_force)
    x_ddot = (force - params.damping * x_dot + params.stiffness * x) / params.mass
    new_x_dot = x_dot + params.dt * x_ddot
    return torch.stack([x + params.dt * new_x_dot, new_x_dot], dim=-1)


class DampedCart(System):
    """Bring the cart from ``x = -1 m`` to the centre and keep it there."""

    name = "damped_cart"
    params_type = DampedCartParams
    state_names = ("x", "x_dot")
    obs_layout = (state_entry(0), state_entry(1))
    main_label = "x [m]"
    main_in_degrees = False
    settling_band = 0.01
    hold_band = 0.05
    hold_min_steps = 50
    operating_region = (0.2, 0.2)
    swing_up_centre = (-1.0, 0.0)
    start_spread = (0.1, 0.1)
    default_q = (1.0, 0.1)
    default_r = (1.0,)
    out_of_bounds_reward = OUT_OF_BOUNDS_REWARD

    params: DampedCartParams

    @property
    def action_limit(self) -> float:
        return float(self.params.max_force)

    def step_fn(self, state: Tensor, action: Tensor) -> Tensor:
        return damped_cart_step(state, action, self.params)

    def reward_fn(self, state: Tensor, action: Tensor) -> Tensor:
        force = torch.clamp(action[..., 0], -self.params.max_force, self.params.max_force)
        return -(
            POSITION_WEIGHT * state[..., 0] ** 2
            + SPEED_WEIGHT * state[..., 1] ** 2
            + FORCE_WEIGHT * force**2
        )

    def out_of_bounds(self, state: Tensor) -> Tensor:
        return torch.abs(state[..., 0]) > self.params.x_limit


def register() -> None:
    """Register ``damped_cart`` (idempotent): ``make_system``, gymnasium and the CLI know it."""
    if "damped_cart" not in system_names():
        register_system("damped_cart", DampedCart)


def main(steps: int = 2_000, run_dir: str | None = None) -> dict[str, float]:
    """Register, design the LQR, train a TD3 hybrid for ``steps`` and compare impulse responses.

    Returns the peak deviation (m) of the LQR's and the hybrid's impulse responses.
    """
    from leoc.control import design_lqr
    from leoc.evaluation.rollout import response_test
    from leoc.policies import LinearController
    from leoc.sb3.train import load_ddpg_controller, train_ddpg
    from leoc.systems import make_system

    register()
    system = make_system("damped_cart")
    design = design_lqr(system)
    print(f"K = {np.round(design.K, 4).tolist()}, spectral radius {design.spectral_radius:.4f}")
    run_dir = run_dir or tempfile.mkdtemp(prefix="damped_cart_")
    train_ddpg(
        "damped_cart",
        "td3",
        hybrid=True,
        total_steps=steps,
        run_dir=run_dir,
        progress=False,
        learning_starts=min(steps // 2, 1_000),
        eval_interval=max(steps // 4, 1),
        eval_episodes=1,
    )
    hybrid = load_ddpg_controller(run_dir)
    linear = LinearController(design.W, design.b)
    peaks = {}
    for label, controller in (("lqr", linear), ("hybrid", hybrid)):
        response = response_test(system, controller, "impulse")
        peaks[label] = float(np.max(np.abs(response.deviation)))
        print(f"{label}: peak deviation {peaks[label]:.4f} m, {response.metrics}")
    return peaks


if __name__ == "__main__":
    main()
