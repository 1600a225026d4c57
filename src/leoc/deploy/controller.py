"""The loaded controller: the whole decision of a run folder, or of a system's LQR alone.

A decision maps one observation (physical units, the system's observation layout) to the
action the actuator receives: the learned part, the relevance, the linear part and the blend
as trained, then the actuator's limits (``Decision``). The action is held for the control
period (``period_steps`` simulator steps, ``period`` seconds) before the next decision: that is
how ``leoc simulate`` runs it, and how a user's loop must run it to see the same closed loop.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
from torch import Tensor, nn

from leoc.systems.rollout import control_period

if TYPE_CHECKING:
    from leoc.control.lqr import LQRDesign
    from leoc.control.roa import LyapunovCertificate
    from leoc.policies.spec import HybridSpec
    from leoc.systems.base import System

__all__ = ["Decision", "DeployedController", "load", "output_saturation"]

DTYPE = torch.float64
DEFAULT_LQR_METHOD = "discrete"  # a run whose config records no ``lqr_method``


class Decision(nn.Module):
    """Observation ``(B, O)`` float64 -> the action ``(B, A)`` the actuator receives:
    ``policy``'s output clipped to ``[low, high]`` (the identity for a policy that saturates
    itself inside the limits; the plant's own clip for the LQR alone and for baselines).

    Parameters
    ----------
    policy : nn.Module
        The controller in physical units (the module of
        :func:`leoc.experiments.controllers.load_trained_controller`).
    low, high : array of shape (A,)
        The actuator's limits.
    """

    low: Tensor
    high: Tensor

    def __init__(self, policy: nn.Module, low: np.ndarray, high: np.ndarray) -> None:
        super().__init__()
        self.policy = policy
        self.register_buffer("low", torch.as_tensor(low, dtype=DTYPE))
        self.register_buffer("high", torch.as_tensor(high, dtype=DTYPE))

    def forward(self, obs: Tensor) -> Tensor:
        """The saturated action of ``obs``."""
        # minimum/maximum rather than clamp with numbers: both export to ONNX in float64
        return torch.minimum(torch.maximum(self.policy(obs), self.low), self.high)


def output_saturation(controller: nn.Module) -> str:
    """The squash of a loaded controller's output: that of its outermost module with a
    ``saturation`` (a hybrid's, or PILCO's ``sin``) or a ``Saturated`` wrapper's ``mode`` (the
    authors' LQR: ``sin``); ``clip`` when it has none or it is the actuator's own clip."""
    from leoc.policies.hybrid import ACTUATOR_CLIPS
    from leoc.policies.saturation import Saturated

    for module in controller.modules():
        saturation = module.mode if isinstance(module, Saturated) else None
        saturation = getattr(module, "saturation", saturation)
        if isinstance(saturation, str):
            return "clip" if saturation in ACTUATOR_CLIPS else saturation
    return "clip"


class DeployedController:
    """A trained controller (or an LQR) ready to run: ``act(observation)`` and what it needs.

    Built by :func:`leoc.deploy.load`. The decision is float64 throughout; call ``act`` once per
    control period and hold the action for ``period_steps`` simulator steps (``period``
    seconds).

    Attributes
    ----------
    module : Decision
        The whole decision as a torch module (what ``leoc export`` writes).
    system : leoc.systems.System
        The plant it was trained on, under the step rules it was trained under.
    design : LQRDesign
        The LQR design of its linear part (for a baseline: the LQR of the same method and
        period it is compared with), ``G(o) = W o + b``.
    hybrid_spec : HybridSpec or None
        The hybrid's spec as saved with the run; None for a baseline and the LQR alone.
    source : str
        The run folder, or ``linear`` for the LQR alone.
    saturation : str
        The squash of its output (``clip``: the actuator's; PILCO: ``sin``).
    """

    def __init__(
        self,
        policy: torch.nn.Module,
        system: System,
        design: LQRDesign,
        hybrid_spec: HybridSpec | None = None,
        source: str = "linear",
    ) -> None:
        limit = np.full(system.action_dim, float(system.action_limit))
        self.module = Decision(policy, -limit, limit).eval()
        self.period_steps = control_period(policy)
        self.system = system
        self.design = design
        self.hybrid_spec = hybrid_spec
        self.source = source
        self.saturation = output_saturation(policy)
        self._certificate: LyapunovCertificate | None = None

    @property
    def period(self) -> float:
        """The control period in seconds: ``period_steps * system.dt``."""
        return self.period_steps * float(self.system.dt)

    @property
    def obs_dim(self) -> int:
        """Entries of one observation (O)."""
        return int(self.system.obs_dim)

    @property
    def action_dim(self) -> int:
        """Entries of one action (A)."""
        return int(self.system.action_dim)

    @property
    def uses_certificate(self) -> bool:
        """Whether its relevance was built on the LQR's proved certificate (the ROA and
        Lyapunov relevances, and the paper's with the floor ``r_min``)."""
        spec = self.hybrid_spec
        return spec is not None and (spec.relevance != "paper" or spec.r_min is not None)

    @property
    def certificate(self) -> LyapunovCertificate | None:
        """The LQR's proved region of attraction its relevance was built on
        (:func:`~leoc.policies.hybrid.lqr_certificate`, proved on first access, cached per
        process); None when its relevance does not use one."""
        if self._certificate is None and self.uses_certificate:
            from leoc.policies.hybrid import lqr_certificate

            self._certificate = lqr_certificate(self.system, self.design, self.saturation)
        return self._certificate

    def act(self, observation: Any) -> Any:
        """The saturated action of one observation ``(O,)`` or a batch ``(B, O)``.

        A numpy array (or list) gives a float64 numpy array ``(A,)`` or ``(B, A)``; a torch
        tensor gives a float64 tensor of the same leading shape.

        Raises
        ------
        ValueError
            The observation does not have O entries in its last axis, or is not finite.
        """
        is_tensor = isinstance(observation, Tensor)
        obs = (
            observation.to(DTYPE) if is_tensor else torch.as_tensor(np.asarray(observation, float))
        )
        if obs.ndim not in (1, 2) or obs.shape[-1] != self.obs_dim:
            raise ValueError(
                f"observation: expected shape ({self.obs_dim},) or (B, {self.obs_dim}), "
                f"found {tuple(obs.shape)}"
            )
        if not bool(torch.isfinite(obs).all()):
            raise ValueError("observation: expected finite numbers, found nan or inf")
        with torch.no_grad():
            action = self.module(obs.reshape(-1, self.obs_dim)).reshape(*obs.shape[:-1], -1)
        return action if is_tensor else action.numpy()

    __call__ = act

    def __repr__(self) -> str:
        kind = "LQR" if self.source == "linear" else self.source
        spec = "" if self.hybrid_spec is None else f", relevance={self.hybrid_spec.relevance!r}"
        return (
            f"DeployedController({kind!r}, system={self.system.name!r}, "
            f"period={self.period_steps} step(s) = {self.period:g} s{spec})"
        )


def load(
    target: str | Path,
    method: str | None = None,
    action_repeat: int = 1,
    variant: str = "leoc",
) -> DeployedController:
    """The controller of a run folder, or the LQR alone of a system, ready to run.

    Parameters
    ----------
    target : str or path
        A run folder written by ``leoc train`` (or printed by ``leoc reproduce``): its
        trained controller (any learner, baseline or hybrid) on the plant it was trained on.
        Or a registered system name (``pendulum``, ...): that system's LQR alone.
    method, action_repeat, variant
        The LQR alone only: its design method (default the variant's), its control period in
        simulator steps, and the variant (``leoc`` or ``authors``) whose LQR and step rules
        it takes.

    Returns
    -------
    DeployedController

    Raises
    ------
    FileNotFoundError
        ``target`` is neither a system name nor a folder holding a controller.
    ValueError
        LQR options given with a run folder, or a file of the run cannot be read.
    """
    from leoc.systems import system_names

    if isinstance(target, str) and target in system_names() and not Path(target).is_dir():
        return _load_lqr(target, method, action_repeat, variant)
    if method is not None or action_repeat != 1 or variant != "leoc":
        raise ValueError(
            "method, action_repeat, variant: expected them only with a system name (the LQR "
            f"alone), found them with the run folder {str(target)!r}"
        )
    return _load_run(Path(target))


def _load_lqr(
    name: str, method: str | None, action_repeat: int, variant_name: str
) -> DeployedController:
    """The variant's LQR of the system ``name`` at ``action_repeat`` (as ``leoc simulate``)."""
    import dataclasses

    from leoc.control import design_lqr
    from leoc.experiments.variants import get_variant
    from leoc.policies import lqr_controller

    variant = get_variant(variant_name)
    if method is not None:
        variant = dataclasses.replace(variant, lqr_method=method)
    system = variant.system(name)
    design = design_lqr(system, method=variant.lqr_method, action_repeat=action_repeat)  # type: ignore[arg-type]
    policy = lqr_controller(design, variant.linear_saturation, system.action_limit)
    return DeployedController(policy, system, design)


def _load_run(run_dir: Path) -> DeployedController:
    """The trained controller of ``run_dir``
    (:func:`leoc.experiments.controllers.load_trained_controller`) with its plant, LQR design
    (its config's method, at the controller's period) and hybrid spec."""
    from leoc.control import design_lqr
    from leoc.experiments.controllers import load_trained_controller, trained_plant, trainer_dir
    from leoc.policies.spec import as_hybrid_spec
    from leoc.training import read_config

    policy = load_trained_controller(run_dir)
    config = read_config(trainer_dir(run_dir))
    system = trained_plant(run_dir)
    method = str(config.get("lqr_method") or DEFAULT_LQR_METHOD)
    design = design_lqr(system, method=method, action_repeat=control_period(policy))  # type: ignore[arg-type]
    spec = as_hybrid_spec(config.get("hybrid"))
    return DeployedController(policy, system, design, spec, source=str(run_dir))
