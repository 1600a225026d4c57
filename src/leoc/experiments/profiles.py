"""Typed settings of the paper's experiments: controllers, profiles and run specifications."""

from __future__ import annotations

import dataclasses
from typing import Any, NamedTuple

from leoc.names import CONTROLLERS, DEFAULT_CONTROLLERS
from leoc.systems import SYSTEM_NAMES, system_names

# Every controller, in report order, and the default set (the paper's controllers and the two
# linear references; the ROA-relevance hybrids are added on request) live in leoc.names, where
# the command line reads them without importing torch.
LINEAR_CONTROLLERS = ("linear", "linear_pilco")
TRAINED_CONTROLLERS = tuple(name for name in CONTROLLERS if name not in ("linear", "linear_pilco"))
# The linear reference of each framework: the LQR designed and run at that framework's control
# period (DDPG acts every simulator step, PILCO holds each action for ``action_repeat`` steps).
LINEAR_REFERENCE = {"ddpg": "linear", "pilco": "linear_pilco"}
CONTROLLER_LABELS = {
    "linear": "linear (LQR at dt)",
    "linear_pilco": "linear (LQR at PILCO's period)",
    "ddpg_baseline": "DDPG baseline",
    "ddpg_hybrid": "DDPG hybrid",
    "ddpg_hybrid_roa": "DDPG hybrid (ROA relevance)",
    "pilco_baseline": "PILCO baseline",
    "pilco_hybrid": "PILCO hybrid",
    "pilco_hybrid_roa": "PILCO hybrid (ROA relevance)",
}


@dataclasses.dataclass(frozen=True)
class Profile:
    """Budgets of one ``leoc reproduce`` profile.

    Attributes
    ----------
    name : str
    seeds : tuple of int
        Training seeds; every controller of every system is trained once per seed.
    pilco_iterations : dict system -> int
        PILCO iterations after the random rollouts (None entries: the PILCO default).
    ddpg_steps : dict system -> int
        DDPG environment steps (None entries: the DDPG default, the paper's 10k / 15k).
    default_pilco_iterations, default_ddpg_steps : int or None
        The budgets of a system missing from the dicts (a user's registered system).
    pilco_overrides, ddpg_overrides : dict
        Further keyword settings passed to the trainers.
    """

    name: str
    seeds: tuple[int, ...]
    pilco_iterations: dict[str, int | None]
    ddpg_steps: dict[str, int | None]
    default_pilco_iterations: int | None = None
    default_ddpg_steps: int | None = None
    pilco_overrides: dict[str, Any] = dataclasses.field(default_factory=dict)
    ddpg_overrides: dict[str, Any] = dataclasses.field(default_factory=dict)
    description: str = ""

    def iterations_for(self, system: str) -> int | None:
        """PILCO iterations of ``system`` (None: the PILCO default)."""
        return self.pilco_iterations.get(system, self.default_pilco_iterations)

    def steps_for(self, system: str) -> int | None:
        """DDPG steps of ``system`` (None: the DDPG default)."""
        return self.ddpg_steps.get(system, self.default_ddpg_steps)


#: The ``leoc reproduce`` profiles by name: ``quick`` (default), ``smoke`` and ``paper``.
PROFILES: dict[str, Profile] = {
    "quick": Profile(
        name="quick",
        seeds=(0,),
        pilco_iterations={"pendulum": 5, "cartpole": 4, "mountaincar": 3},
        ddpg_steps={"pendulum": 5000, "cartpole": 8000, "mountaincar": 6000},
        pilco_overrides={"policy_iterations": 40},
        description=(
            "quick profile: one seed and reduced training budgets (real training, not the "
            "paper's budgets); numbers are indicative, not a reproduction of the paper's"
        ),
    ),
    "smoke": Profile(
        name="smoke",
        seeds=(0,),
        pilco_iterations={name: 1 for name in SYSTEM_NAMES},
        ddpg_steps={name: 400 for name in SYSTEM_NAMES},
        default_pilco_iterations=1,
        default_ddpg_steps=400,
        pilco_overrides={
            "horizon": 10,
            "num_basis": 5,
            "policy_iterations": 3,
            "initial_rollouts": 1,
        },
        ddpg_overrides={
            "learning_starts": 100,
            "eval_interval": 200,
            "eval_episodes": 1,
            "actor_hidden": (32, 32),
            "critic_hidden": (32, 32),
        },
        description=(
            "smoke profile: a tiny end-to-end check of the pipeline (a few hundred steps of "
            "training); its controllers are not trained and its numbers mean nothing"
        ),
    ),
    "paper": Profile(
        name="paper",
        seeds=(0, 1, 2),
        pilco_iterations={name: None for name in SYSTEM_NAMES},
        ddpg_steps={name: None for name in SYSTEM_NAMES},
        description="paper profile: the paper's budgets (appendix C) over three seeds",
    ),
}
PROFILE_NAMES = tuple(PROFILES)


def get_profile(name: str, seeds: int | None = None) -> Profile:
    """The named profile, optionally with its seeds replaced by ``0 .. seeds - 1``."""
    if name not in PROFILES:
        raise ValueError(f"profile: expected one of {', '.join(PROFILES)}, found {name!r}")
    profile = PROFILES[name]
    if seeds is not None:
        if seeds < 1:
            raise ValueError(f"seeds: expected a positive integer, found {seeds}")
        profile = dataclasses.replace(profile, seeds=tuple(range(seeds)))
    return profile


class RunSpec(NamedTuple):
    """One unit of work: a controller of a system, for one seed."""

    system: str
    controller: str
    seed: int

    @property
    def key(self) -> str:
        """Run folder path ``system/controller/seedN`` under the output folder's ``runs``."""
        return f"{self.system}/{self.controller}/seed{self.seed}"

    @property
    def framework(self) -> str:
        """``linear``, ``ddpg`` or ``pilco``."""
        return "linear" if self.controller in LINEAR_CONTROLLERS else self.controller.split("_")[0]

    @property
    def hybrid(self) -> bool:
        """Whether the controller is a hybrid."""
        return "_hybrid" in self.controller

    @property
    def relevance(self) -> str:
        """The hybrid's relevance: ``roa`` for the ``*_hybrid_roa`` controllers, else ``paper``."""
        return "roa" if self.controller.endswith("_roa") else "paper"


def run_specs(
    profile: Profile,
    systems: tuple[str, ...] = SYSTEM_NAMES,
    controllers: tuple[str, ...] = DEFAULT_CONTROLLERS,
) -> list[RunSpec]:
    """Every run of a profile, the longest first (cart-pole, PILCO) to balance the workers.

    ``systems``: registered names (default: the paper's three)."""
    known = system_names()
    for name in systems:
        if name not in known:
            raise ValueError(f"systems: unknown {name!r}; expected some of {known}")
    for name in controllers:
        if name not in CONTROLLERS:
            raise ValueError(f"controllers: unknown {name!r}; expected some of {CONTROLLERS}")
    specs = [
        RunSpec(system, controller, seed)
        for system in systems
        for controller in controllers
        for seed in (profile.seeds if controller not in LINEAR_CONTROLLERS else (0,))
    ]
    cost = {"pilco": 2, "ddpg": 1, "linear": 0}
    return sorted(specs, key=lambda spec: -cost[spec.framework])
