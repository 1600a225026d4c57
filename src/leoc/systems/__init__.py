"""Systems: physics, observation maps, operating points, starts, gymnasium envs, registry.

The built-in systems (the paper's three and the acrobot) are registered here; a user's system
is added with :func:`register_system` (see ``docs/user_guide/custom_system.md``).
"""

from __future__ import annotations

from leoc.systems.base import (
    DEFAULT_EPISODE_STEPS,
    DTYPE,
    START_KINDS,
    PhysicalParams,
    StepRules,
    System,
    wrap_angle,
)
from leoc.systems.cartpole import CartPole, CartPoleParams, cartpole_reward, cartpole_step
from leoc.systems.envs import BUILTIN_ENVS, LeocEnv, make_env
from leoc.systems.mountaincar import (
    MountainCar,
    MountainCarParams,
    mountaincar_reward,
    mountaincar_step,
)
from leoc.systems.observation import ObsComponent, ObservationMap, angle_entries, state_entry
from leoc.systems.pendulum import Pendulum, PendulumParams, pendulum_reward, pendulum_step
from leoc.systems.perturbation_levels import (
    PUSHES_PER_EPISODE,
    RANDOMISATION_STREAM,
    SELECTION_STREAM,
    TWO_SIDED_CATEGORIES,
    EpisodeDraw,
    EpisodePlants,
    TrainingPerturbations,
    category_perturbations,
)
from leoc.systems.perturbations import (
    ActionDelay,
    ActuatorGain,
    Friction,
    ObservationNoise,
    ParameterError,
    Perturbation,
    PerturbedPlant,
    Push,
    TorqueNoise,
)
from leoc.systems.registry import (
    env_id,
    make_system,
    register_system,
    system_names,
    unregister_system,
)

# The paper's three benchmark systems (what `leoc reproduce` runs by default).
#: The paper's three systems, by registry name.
PAPER_SYSTEMS: dict[str, type[System]] = {
    "pendulum": Pendulum,
    "cartpole": CartPole,
    "mountaincar": MountainCar,
}
#: Registry names of the paper's three systems (what ``leoc reproduce`` runs by default).
SYSTEM_NAMES = tuple(PAPER_SYSTEMS)

for _name, _factory in PAPER_SYSTEMS.items():
    _env_id, _env_class = BUILTIN_ENVS[_name]
    register_system(
        _name,
        _factory,
        _env_id,
        entry_point=f"{_env_class.__module__}:{_env_class.__name__}",
        replace=True,
    )

# The acrobot, built only through the public protocol: its registry entry is all it needs here.
from leoc.systems.acrobot import Acrobot  # noqa: E402

register_system("acrobot", Acrobot, replace=True)

__all__ = [
    "PUSHES_PER_EPISODE",
    "RANDOMISATION_STREAM",
    "SELECTION_STREAM",
    "TWO_SIDED_CATEGORIES",
    "EpisodeDraw",
    "EpisodePlants",
    "TrainingPerturbations",
    "category_perturbations",
    "ActionDelay",
    "ActuatorGain",
    "Friction",
    "ObservationNoise",
    "ParameterError",
    "Perturbation",
    "PerturbedPlant",
    "Push",
    "TorqueNoise",
    "DEFAULT_EPISODE_STEPS",
    "DTYPE",
    "PAPER_SYSTEMS",
    "START_KINDS",
    "SYSTEM_NAMES",
    "CartPole",
    "CartPoleParams",
    "LeocEnv",
    "MountainCar",
    "MountainCarParams",
    "ObsComponent",
    "ObservationMap",
    "Pendulum",
    "PendulumParams",
    "PhysicalParams",
    "StepRules",
    "System",
    "angle_entries",
    "cartpole_reward",
    "cartpole_step",
    "env_id",
    "make_env",
    "make_system",
    "mountaincar_reward",
    "mountaincar_step",
    "pendulum_reward",
    "pendulum_step",
    "register_system",
    "state_entry",
    "system_names",
    "unregister_system",
    "wrap_angle",
]
