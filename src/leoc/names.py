"""Names the command line needs before anything heavy is imported.

The ``leoc`` command builds its parser (and answers ``--help``) from these tuples without
importing torch, gymnasium's environments or the systems. The modules that own each name re-use
them, and ``tests/test_cli.py`` checks that they agree with the registry and the profiles.
"""

from __future__ import annotations

PAPER_SYSTEM_NAMES = ("pendulum", "cartpole", "mountaincar")
"""The paper's three benchmark systems (what ``leoc reproduce`` runs by default)."""
BUILTIN_SYSTEM_NAMES = (*PAPER_SYSTEM_NAMES, "acrobot")
"""Every system ``leoc.systems`` registers on import."""
BUILTIN_EPISODE_STEPS = 200
"""Episode length of every built-in system (the gymnasium ``TimeLimit``)."""
GENERIC_ENTRY_POINT = "leoc.systems.envs:LeocEnv"
BUILTIN_ENV_IDS = {
    "pendulum": ("leoc/PendulumSwingUp-v0", "leoc.systems.envs:PendulumSwingUpEnv"),
    "cartpole": ("leoc/CartPoleSwingUp-v0", "leoc.systems.envs:CartPoleSwingUpEnv"),
    "mountaincar": ("leoc/MountainCarHilltop-v0", "leoc.systems.envs:MountainCarHilltopEnv"),
    "acrobot": ("leoc/Acrobot-v0", GENERIC_ENTRY_POINT),
}
"""Gymnasium id and entry point of each built-in system (``import leoc`` registers them)."""

CONTROLLERS = (
    "linear",
    "linear_pilco",
    "ddpg_baseline",
    "ddpg_hybrid",
    "ddpg_hybrid_roa",
    "pilco_baseline",
    "pilco_hybrid",
    "pilco_hybrid_roa",
)
"""Every controller ``leoc reproduce`` knows, in report order."""
DEFAULT_CONTROLLERS = tuple(name for name in CONTROLLERS if not name.endswith("_roa"))
"""What ``leoc reproduce`` runs unless ``--controllers`` says otherwise: the paper's controllers
and the two linear references (the ROA-relevance hybrids are added on request)."""
PROFILE_NAMES = ("quick", "smoke", "paper")
"""The profiles of ``leoc reproduce`` (``leoc.experiments.profiles.PROFILES``, same order)."""


def register_builtin_envs() -> None:
    """Register the built-in systems' gymnasium ids by entry point, without building them.

    ``gymnasium.make`` of one of these ids imports :mod:`leoc.systems.envs`, which imports
    :mod:`leoc.systems` and registers every system in full (an id registered here is replaced
    there). So ``import leoc`` keeps gymnasium's convention (importing the package registers its
    environments) without importing torch.
    """
    import gymnasium as gym

    for name, (env_id, entry_point) in BUILTIN_ENV_IDS.items():
        if env_id in gym.registry:
            continue
        kwargs = {"system": name} if entry_point == GENERIC_ENTRY_POINT else {}
        gym.register(
            id=env_id,
            entry_point=entry_point,
            max_episode_steps=BUILTIN_EPISODE_STEPS,
            kwargs=kwargs,
        )
