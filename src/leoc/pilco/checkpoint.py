"""PILCO's run state on disk: the resumable checkpoint and the saved controller.

``checkpoint.pt`` holds everything needed to resume (data, RNG states, GP hyper-parameters,
policy); ``controller.pt`` the policy, GP posterior and config. Both are written atomically; a
damaged checkpoint is set aside and the run starts afresh. ``controller.pt`` loads back as the
controller (:func:`load_pilco_controller`) or as the whole trained run, policy and GP model,
predicting as the trainer did (:func:`load_pilco_run`).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import torch
from torch import nn

from leoc.io import save_torch_atomic, set_aside
from leoc.pilco.config import PilcoConfig
from leoc.pilco.gp import GPHyper, GPPosterior
from leoc.pilco.objective import predict_policy
from leoc.pilco.policy import build_policy
from leoc.pilco.propagate import Prediction
from leoc.policies import HeldPolicy
from leoc.systems.base import System
from leoc.training import config_differences

CHECKPOINT_NAME = "checkpoint.pt"
CONTROLLER_NAME = "controller.pt"


class BestPolicy(NamedTuple):
    """The policy kept by ``PilcoConfig.select_best_from``: its iteration, mean evaluation
    return and parameters."""

    iteration: int
    mean_return: float
    policy_state: dict[str, torch.Tensor]


class RunState(NamedTuple):
    iteration: int
    inputs: np.ndarray
    targets: np.ndarray
    interaction_steps: int
    log: list[dict[str, Any]]
    rng_state: dict[str, Any]
    hyper: GPHyper | None
    best: BestPolicy | None = None


def save_checkpoint(
    run_dir: Path,
    config: PilcoConfig,
    state: RunState,
    policy: nn.Module,
    model: GPPosterior | None,
    generator: torch.Generator,
) -> None:
    save_torch_atomic(
        {
            "config": config.to_dict(),
            "iteration": state.iteration,
            "inputs": state.inputs,
            "targets": state.targets,
            "interaction_steps": state.interaction_steps,
            "log": state.log,
            "rng_state": state.rng_state,
            "torch_rng_state": generator.get_state(),
            "hyper": None if state.hyper is None else state.hyper._asdict(),
            "policy_state": policy.state_dict(),
            "model": None if model is None else model._asdict(),
            "best": None if state.best is None else state.best._asdict(),
        },
        run_dir / CHECKPOINT_NAME,
    )
    save_controller(run_dir, config, policy.state_dict(), model)


def save_controller(
    run_dir: Path,
    config: PilcoConfig,
    policy_state: dict[str, torch.Tensor],
    model: GPPosterior | None,
) -> None:
    """Write ``controller.pt``: the run's controller (policy parameters), GP posterior, config."""
    save_torch_atomic(
        {
            "config": config.to_dict(),
            "policy_state": policy_state,
            "model": None if model is None else model._asdict(),
        },
        run_dir / CONTROLLER_NAME,
    )


def resume_checkpoint(
    run_dir: Path, config: PilcoConfig, system: System, generator: torch.Generator
) -> tuple[RunState, nn.Module, GPPosterior | None] | None:
    path = run_dir / CHECKPOINT_NAME
    if not path.exists():
        return None
    try:
        saved = torch.load(path, weights_only=False)
        old = PilcoConfig.from_dict(saved["config"])
    except Exception as error:  # truncated or garbled: set it aside and start afresh
        aside = set_aside(path)
        print(
            f"[pilco] damaged checkpoint {path} ({type(error).__name__}: {error}); set aside as "
            f"{aside.name}, starting the run afresh",
            flush=True,
        )
        return None
    if dataclasses.replace(old, iterations=config.iterations) != config:
        differences = config_differences(old.to_dict(), config.to_dict())
        raise ValueError(
            f"run folder: {str(run_dir)!r} holds a PILCO run of another configuration "
            f"({'; '.join(differences[:3])}); pass --overwrite (resume=False) to replace it, or "
            "choose another folder (--out)"
        )
    if saved["iteration"] > config.iterations:
        raise ValueError(
            f"iterations: {str(run_dir)!r} holds a PILCO run of {saved['iteration']} iterations, "
            f"more than the {config.iterations} asked for; ask for at least "
            f"{saved['iteration']} to extend it, or pass --overwrite (resume=False) to replace it"
        )
    generator.set_state(saved["torch_rng_state"])
    policy = build_policy(system, config, generator)
    policy.load_state_dict(saved["policy_state"])
    hyper = None if saved["hyper"] is None else GPHyper(**saved["hyper"])
    model = None if saved["model"] is None else GPPosterior(**saved["model"])
    state = RunState(
        saved["iteration"],
        saved["inputs"],
        saved["targets"],
        saved["interaction_steps"],
        saved["log"],
        saved["rng_state"],
        hyper,
        None if saved.get("best") is None else BestPolicy(**saved["best"]),
    )
    return state, policy, model


class _SavedController(NamedTuple):
    """``controller.pt`` as read: its path, config, policy parameters and GP posterior (None
    before the run's first PILCO iteration)."""

    path: Path
    config: PilcoConfig
    policy_state: dict[str, torch.Tensor]
    model: GPPosterior | None


def _read_controller(run_dir: str | Path) -> _SavedController:
    """Read ``run_dir/controller.pt``; a missing file raises FileNotFoundError, a truncated or
    garbled one a one-line ValueError naming it."""
    path = Path(run_dir) / CONTROLLER_NAME
    try:
        saved = torch.load(path, weights_only=False)
        config = PilcoConfig.from_dict(saved["config"])
        model = None if saved["model"] is None else GPPosterior(**saved["model"])
        policy_state = saved["policy_state"]
    except FileNotFoundError:
        raise
    except Exception as error:  # a truncated or garbled file: name it
        raise ValueError(
            f"controller: {path} could not be read as a PILCO controller "
            f"({type(error).__name__}: {error})"
        ) from error
    return _SavedController(path, config, policy_state, model)


def _saved_policy(system: System, saved: _SavedController) -> nn.Module:
    """The saved policy (observation -> action, as PILCO's prediction runs it), in eval mode."""
    policy = build_policy(system, saved.config, torch.Generator().manual_seed(0))
    policy.load_state_dict(saved.policy_state)
    return policy.eval()


def load_pilco_controller(run_dir: str | Path) -> nn.Module:
    """The trained policy of a run folder at its control period (a
    :class:`~leoc.policies.HeldPolicy`: observations -> physical actions)."""
    saved = _read_controller(run_dir)
    policy = _saved_policy(saved.config.plant(), saved)
    return HeldPolicy(policy, saved.config.controller_action_repeat).eval()


class PilcoRun(NamedTuple):
    """A trained PILCO run loaded back from its folder (:func:`load_pilco_run`).

    Attributes
    ----------
    config : PilcoConfig
        The run's settings.
    system : leoc.systems.System
        The plant it trained on (:meth:`PilcoConfig.plant`: its step rules and episode length).
    policy : torch.nn.Module
        The saved policy, observation (O,) -> action (F,) in physical units, as PILCO's horizon
        prediction runs it (the saturated RBF network, or the hybrid), in eval mode.
    model : GPPosterior
        The run's last GP dynamics model: ``gp_predict(model, x)`` at inputs ``x`` (B, D), the
        observation (angles as cos/sin) then the action, gives the mean (B, E) and the latent
        variance (B, E, noise excluded) of the state change over one decision
        (``action_repeat`` simulator steps).
    run_dir : Path
        The folder it was loaded from.
    """

    config: PilcoConfig
    system: System
    policy: torch.nn.Module
    model: GPPosterior
    run_dir: Path

    @property
    def controller(self) -> HeldPolicy:
        """The policy at its control period, as :func:`load_pilco_controller` returns it."""
        return HeldPolicy(self.policy, self.config.controller_action_repeat).eval()

    def predict(self) -> Prediction:
        """The horizon prediction PILCO optimises the policy on: from the config's start
        distribution over ``horizon`` decisions, with its saturating cost (no gradients)."""
        with torch.no_grad():
            return predict_policy(self.policy, self.model, self.system, self.config)


def load_pilco_run(run_dir: str | Path) -> PilcoRun:
    """The trained policy and GP dynamics model of a PILCO run folder (``controller.pt``),
    ready to predict as the trainer did.

    Parameters
    ----------
    run_dir : path
        A folder written by :func:`~leoc.pilco.train_pilco` (or ``leoc train --algo pilco``).

    Returns
    -------
    PilcoRun
        Its config, plant, policy and GP model; ``run.predict()`` is the horizon prediction
        and ``gp_predict(run.model, x)`` the one-step one.

    Raises
    ------
    FileNotFoundError
        If ``run_dir`` holds no ``controller.pt``.
    ValueError
        If the file cannot be read (the message names it), or it holds no GP model yet (saved
        before the run's first PILCO iteration completed).
    """
    saved = _read_controller(run_dir)
    if saved.model is None:
        raise ValueError(
            f"controller: {saved.path} holds no GP model yet (saved before the run's first PILCO "
            "iteration completed); resume the run (train_pilco with this run_dir) to fit one"
        )
    system = saved.config.plant()
    return PilcoRun(saved.config, system, _saved_policy(system, saved), saved.model, Path(run_dir))
