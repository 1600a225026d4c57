"""The three benchmark systems: physics, operating points, starts and gymnasium envs."""

from __future__ import annotations

from leoc.systems.base import (
    DEFAULT_EPISODE_STEPS,
    DTYPE,
    START_KINDS,
    ObsComponent,
    PhysicalParams,
    System,
    wrap_angle,
)
from leoc.systems.cartpole import CartPole, CartPoleParams, cartpole_reward, cartpole_step
from leoc.systems.envs import ENV_CLASSES, ENV_IDS, LeocEnv, register_envs
from leoc.systems.mountaincar import (
    MountainCar,
    MountainCarParams,
    mountaincar_reward,
    mountaincar_step,
)
from leoc.systems.pendulum import Pendulum, PendulumParams, pendulum_reward, pendulum_step

SYSTEMS: dict[str, type[System]] = {
    "pendulum": Pendulum,
    "cartpole": CartPole,
    "mountaincar": MountainCar,
}
SYSTEM_NAMES = tuple(SYSTEMS)


def make_system(name: str, params: PhysicalParams | None = None, **scales: float) -> System:
    """Build a system by registry name, optionally with parameters scaled (``mass=2.0``).

    Raises
    ------
    ValueError
        If ``name`` is not one of :data:`SYSTEM_NAMES`.
    """
    if name not in SYSTEMS:
        raise ValueError(f"system: unknown name {name!r}; expected one of {', '.join(SYSTEMS)}")
    system = SYSTEMS[name](params)
    return system.with_params(**scales) if scales else system


def make_env(name: str, params: PhysicalParams | None = None, **kwargs: object) -> LeocEnv:
    """``gymnasium.make`` of the registered env of system ``name`` (with its TimeLimit)."""
    import gymnasium as gym

    if name not in ENV_IDS:
        raise ValueError(f"system: unknown name {name!r}; expected one of {', '.join(ENV_IDS)}")
    return gym.make(ENV_IDS[name], params=params, **kwargs)


register_envs()

__all__ = [
    "DEFAULT_EPISODE_STEPS",
    "DTYPE",
    "ENV_CLASSES",
    "ENV_IDS",
    "START_KINDS",
    "SYSTEMS",
    "SYSTEM_NAMES",
    "CartPole",
    "CartPoleParams",
    "LeocEnv",
    "MountainCar",
    "MountainCarParams",
    "ObsComponent",
    "Pendulum",
    "PendulumParams",
    "PhysicalParams",
    "System",
    "cartpole_reward",
    "cartpole_step",
    "make_env",
    "make_system",
    "mountaincar_reward",
    "mountaincar_step",
    "pendulum_reward",
    "pendulum_step",
    "register_envs",
    "wrap_angle",
]
