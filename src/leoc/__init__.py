"""leoc: Locally Enforced Optimal Controllers.

A hybrid controller pi(x) = r(x) G(x) + (1 - r(x)) H(x) that equals an LQR design G near an
operating point and a learned policy H elsewhere (Zhang & Capel, L4DC 2021).
"""

__version__ = "0.1.0"

import importlib
from typing import Any

from leoc.names import register_builtin_envs_with_gymnasium

# gymnasium convention: importing the package registers its environments (leoc/...-v0). The ids
# are registered by entry point (now, or when gymnasium is first imported), so ``import leoc``
# (and the ``leoc`` command's start-up) imports neither torch nor gymnasium; ``leoc.systems``
# registers each system in full when first imported.
register_builtin_envs_with_gymnasium()

_SUBPACKAGES = ("control", "evaluation", "experiments", "pilco", "policies", "sb3", "systems")


def __getattr__(name: str) -> Any:
    """``leoc.systems`` and the other subpackages, imported on first access."""
    if name in _SUBPACKAGES:
        return importlib.import_module(f"leoc.{name}")
    raise AttributeError(f"module 'leoc' has no attribute {name!r}")
