"""leoc: Locally Enforced Optimal Controllers.

A hybrid controller pi(x) = r(x) G(x) + (1 - r(x)) H(x) that equals an LQR design G near an
operating point and a learned policy H elsewhere (Zhang & Capel, L4DC 2021).
"""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import TYPE_CHECKING, Any

from leoc.names import register_builtin_envs_with_gymnasium

__version__ = "0.1.0"

# gymnasium convention: importing the package registers its environments (leoc/...-v0). The ids
# are registered by entry point (now, or when gymnasium is first imported), so ``import leoc``
# (and the ``leoc`` command's start-up) imports neither torch nor gymnasium; ``leoc.systems``
# registers each system in full when first imported.
if TYPE_CHECKING:
    from leoc.deploy import DeployedController

register_builtin_envs_with_gymnasium()

_SUBPACKAGES = (
    "control",
    "deploy",
    "evaluation",
    "experiments",
    "pilco",
    "policies",
    "sb3",
    "systems",
)


def load(
    target: str | Path, method: str | None = None, action_repeat: int = 1, variant: str = "leoc"
) -> DeployedController:
    """A trained controller (or a system's LQR alone), ready to run: ``act(observation)``.

    ``leoc.load(RUN_DIR)`` loads the controller of a ``leoc train`` (or ``leoc reproduce``)
    run folder, any learner, baseline or hybrid, on the plant it was trained on;
    ``leoc.load("pendulum")`` the system's LQR (``method``, ``action_repeat`` and
    ``variant`` choose its design). Imports torch on the first call, not with ``leoc``.

    Parameters
    ----------
    target : str or path
        A run folder, or a registered system name.
    method : str, optional
        The LQR alone: its design method (default the variant's).
    action_repeat : int
        The LQR alone: its control period in simulator steps (default 1).
    variant : str
        The LQR alone: ``leoc`` (default) or ``authors``.

    Returns
    -------
    leoc.deploy.DeployedController
        Its ``act``, control period, system, LQR design, hybrid spec and certificate
        (``docs/user_guide/deploy.md``).
    """
    from leoc.deploy import load as load_controller

    return load_controller(target, method, action_repeat, variant)


def __getattr__(name: str) -> Any:
    """``leoc.systems`` and the other subpackages, imported on first access."""
    if name in _SUBPACKAGES:
        return importlib.import_module(f"leoc.{name}")
    raise AttributeError(f"module 'leoc' has no attribute {name!r}")
