r"""float64 policies in physical units, built from a trained SB3 actor's weights.

SB3 actors work in float32 and output normalised actions in [-1, 1]. For evaluation (responses,
robustness sweeps, region of attraction) we want a plain torch module mapping float64
observations (B, D) to physical actions (B, F). :func:`physical_policy` builds it:

* baseline actor: :math:`\pi(x) = c + h \odot \tanh(\mathrm{MLP}(x))` (for SAC its
  deterministic action, the squashed mean :math:`c + h \odot \tanh M(x)`);
* hybrid actor: :math:`\pi(x) = \operatorname{clip}_{[u_{low}, u_{high}]}(r G + (1 - r) H)`
  with :math:`G(x) = W x + b` from the actor's float64 buffers (the LQR design itself, not its
  float32 rescaling) and :math:`H = c + h \odot \tanh(\mathrm{MLP})` (SAC:
  :math:`c + h \odot \tanh M`), so that :math:`\pi(a) = G(a)` and
  :math:`\partial\pi/\partial x(a) = W` hold to float64 round-off.

The MLP weights and :math:`\lambda` are the actor's, converted to float64; the result agrees
with the SB3 actor's deterministic action to float32 precision (for the SAC hybrid, whose
squashed mean is :math:`\tanh\operatorname{atanh}` of the clipped blend, also to
:math:`\epsilon h` where the clip acts, :mod:`leoc.sb3.sac`).
"""

from __future__ import annotations

import copy
import math
from typing import Any

import numpy as np
import torch
from stable_baselines3.sac.policies import Actor as SACActor
from stable_baselines3.sac.policies import SACPolicy
from stable_baselines3.td3.policies import Actor, TD3Policy
from torch import Tensor, nn

from leoc.policies import HybridPolicy, LinearController, PrecisionRelevance
from leoc.policies.relevance import FlatRegion
from leoc.sb3.common import HybridActorMixin, action_box
from leoc.sb3.sac import SquashedMean

__all__ = ["AffineOutput", "PhysicalPolicy", "physical_policy"]

DTYPE = torch.float64


class AffineOutput(nn.Module):
    """``c + h * module(x)``: a normalised-action module mapped to physical units.

    Shapes: (B, D) -> (B, F); ``centre`` and ``half_width`` are (F,) buffers.
    """

    centre: Tensor
    half_width: Tensor

    def __init__(self, module: nn.Module, centre: np.ndarray, half_width: np.ndarray) -> None:
        super().__init__()
        self.module = module
        self.register_buffer("centre", torch.as_tensor(centre, dtype=DTYPE))
        self.register_buffer("half_width", torch.as_tensor(half_width, dtype=DTYPE))

    def forward(self, x: Tensor) -> Tensor:
        return self.centre + self.half_width * self.module(x)


class PhysicalPolicy(nn.Module):
    r"""Deterministic policy in physical units: float64 (B, D) observations -> (B, F) actions.

    ``core`` computes the unsaturated action; the output is clipped to the action box
    :math:`[u_{low}, u_{high}]` (the identity strictly inside it). For a hybrid, ``hybrid`` is
    the float64 :class:`~leoc.policies.HybridPolicy` (for relevance traces) and ``core`` is its
    unsaturated blend.

    Attributes
    ----------
    low, high : Tensor
        (F,) float64 action bounds.
    hybrid : HybridPolicy or None
        The blend for a hybrid actor, ``None`` for a baseline.
    """

    low: Tensor
    high: Tensor

    def __init__(
        self,
        core: nn.Module,
        low: np.ndarray,
        high: np.ndarray,
        hybrid: HybridPolicy | None = None,
    ) -> None:
        super().__init__()
        self.core = core
        self.hybrid = hybrid
        self.register_buffer("low", torch.as_tensor(low, dtype=DTYPE))
        self.register_buffer("high", torch.as_tensor(high, dtype=DTYPE))

    @property
    def is_hybrid(self) -> bool:
        """Whether the actor is a hybrid (it has a relevance r(x))."""
        return self.hybrid is not None

    def forward(self, x: Tensor) -> Tensor:
        """Physical action ``(B, F)`` of float64 observations ``(B, D)``."""
        unsaturated = self.hybrid.blend(x) if self.hybrid is not None else self.core(x)
        return self._clip(unsaturated)

    def flat_region(self) -> FlatRegion | None:
        """The hybrid's :meth:`~leoc.policies.HybridPolicy.flat_region`, its controller clipped
        to the action box as this policy's output is; None for a baseline."""
        region = None if self.hybrid is None else self.hybrid.flat_region(saturated=False)
        if region is None:
            return None
        linear = region.inner
        return region._replace(inner=lambda x: self._clip(linear(x)))

    def _clip(self, action: Tensor) -> Tensor:
        return torch.minimum(torch.maximum(action, self.low), self.high)

    def relevance(self, x: Tensor) -> Tensor:
        """Relevance ``r(x)`` (B, 1) of the linear part; zeros for a baseline policy."""
        if self.hybrid is None:
            return torch.zeros(x.shape[:-1] + (1,), dtype=x.dtype)
        return self.hybrid.relevance(x)


#: Relevance modules whose one learned tensor (named here) is copied into a float64 rebuild.
LEARNED_RELEVANCE = {
    "FlooredRelevance": "log_excess",
    "LyapunovRelevance": "log_lambda",
    "PaperRelevance": "log_lambda",
}


def _frozen_relevance64(actor: HybridActorMixin) -> dict[str, Any]:
    """Keywords of :class:`~leoc.policies.HybridPolicy` for a float64, frozen copy of the
    actor's learned relevance."""
    module = actor.hybrid.relevance_module
    if module is None:
        return {"lambda_init": actor.hybrid.lambda_.detach().cpu().to(DTYPE), "learn_lambda": False}
    if isinstance(module, PrecisionRelevance):
        # float64 copy of the learned precision S, frozen (any sign: the authors' S is
        # unconstrained, so it is copied, not rebuilt through the positive constructor)
        copy64 = PrecisionRelevance(actor.operating_obs.detach().cpu(), 1.0, False, DTYPE)
        copy64.precision.copy_(module.precision.detach().cpu().to(DTYPE))
        return {"relevance": copy64}
    learned = LEARNED_RELEVANCE.get(type(module).__name__)
    if learned is not None:
        # rebuilt in float64 from the design data (the floor, P, rho stay exact), frozen, with
        # the learned parameter copied over
        frozen = actor.hybrid_spec.replace(learn_lambda=False)
        data = actor.hybrid_design.relevance_data
        built = frozen.design.build(frozen, data, actor.operating_obs.cpu().numpy(), DTYPE)
        getattr(built["relevance"], learned).copy_(getattr(module, learned).detach().cpu())
        return built
    # Any other design is rebuilt in float64 from the actor's float64 design data (the ROA
    # relevance's P, rho_in) with its learned band width, frozen. float32 sigmoid can round w up
    # to w_max itself; the float64 rebuild needs w < w_max.
    width = min(float(module.width.detach()), math.nextafter(module.max_width, 0.0))
    frozen = actor.hybrid_spec.replace(width_init=width, learn_width=False)
    data = actor.hybrid_design.relevance_data
    return frozen.design.build(frozen, data, actor.operating_obs.cpu().numpy(), DTYPE)


def physical_policy(actor: Actor | SACActor | TD3Policy | SACPolicy) -> PhysicalPolicy:
    """float64 physical-units copy of an SB3 DDPG/TD3 or SAC actor, baseline or hybrid
    (:class:`~leoc.sb3.HybridActor`, :class:`~leoc.sb3.HybridSACActor`): its deterministic
    action.

    Parameters
    ----------
    actor : SB3 actor or policy
        ``model.actor`` of an SB3 ``DDPG``/``TD3``/``SAC`` model, or ``model.policy`` (the
        policy's ``actor`` is taken; both give the same copy).

    Returns
    -------
    PhysicalPolicy
        The copy: it shares nothing with ``actor`` (later training does not change it) and has
        no trainable parameters (all ``requires_grad`` off; gradients with respect to the
        *input* still flow, so autograd Jacobians work).

    Raises
    ------
    TypeError
        If ``actor`` is neither an SB3 DDPG/TD3 or SAC actor nor a policy holding one (for a
        model, pass ``model.policy``).
    """
    if isinstance(actor, (TD3Policy, SACPolicy)):
        actor = actor.actor
    if not isinstance(actor, (Actor, SACActor)):
        raise TypeError(
            "actor: expected an SB3 DDPG/TD3 or SAC actor or policy (physical_policy(model.policy)"
            f" or physical_policy(model.actor)), found {type(actor).__name__}"
        )
    centre, half = action_box(actor.action_space)
    low = np.asarray(actor.action_space.low, dtype=np.float64).reshape(-1)
    high = np.asarray(actor.action_space.high, dtype=np.float64).reshape(-1)
    if isinstance(actor, HybridActorMixin):
        mlp = copy.deepcopy(actor.hybrid.nonlinear).to(device="cpu", dtype=DTYPE)
        relevance = _frozen_relevance64(actor)
        hybrid = HybridPolicy(
            LinearController(actor.physical_gain.detach().cpu(), actor.physical_bias.cpu()),
            AffineOutput(mlp, centre, half),
            actor.operating_obs.detach().cpu(),
            action_limit=None,
            saturation="none",
            **relevance,  # type: ignore[arg-type]
        )
        policy = PhysicalPolicy(hybrid, low, high, hybrid=hybrid)
    else:
        mean = actor.mu if isinstance(actor, Actor) else SquashedMean(actor.latent_pi, actor.mu)
        mlp = copy.deepcopy(mean).to(device="cpu", dtype=DTYPE)
        policy = PhysicalPolicy(AffineOutput(mlp, centre, half), low, high)
    policy.requires_grad_(False)
    return policy.eval()
