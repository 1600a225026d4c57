r"""Stable-Baselines3's TD3 with the LEOC hybrid: its actor, its policies and the algorithm.

Adapts ``stable_baselines3.td3``: :class:`HybridActor` is SB3's TD3 ``Actor`` whose output is the
LEOC blend of an LQR controller and SB3's MLP (:class:`~leoc.sb3.common.HybridActorMixin`; units
and identities in :mod:`leoc.sb3.common`); :class:`LeocTD3Policy` is SB3's ``TD3Policy`` with the
critic layout and the networks' initialisation as options; :class:`HybridTD3Policy` is that
policy with hybrid actor and target actor; :class:`LeocTD3` is SB3's ``TD3`` with the paper's
settings (``actor_learning_rate``, ``target_update_interval``, ``warmup``, ``critic_loss``,
``target_action_clip``; :mod:`leoc.sb3.common`). SB3's DDPG uses TD3's policy classes, so these
serve :mod:`leoc.sb3.ddpg` too.

The LEOC policy (:class:`HybridTD3Policy`) also works with plain ``stable_baselines3.DDPG`` and
``TD3``; :class:`LeocTD3` only reproduces the paper's settings.

References
----------
S. Fujimoto, H. van Hoof and D. Meger, "Addressing Function Approximation Error in Actor-Critic
Methods", ICML 2018.
Y. Zhang and F. Capel, "LEOC: A Principled Method in Integrating Reinforcement Learning and
Classical Control Theory", L4DC 2021, eq. 4-5 and appendix C.
"""

from __future__ import annotations

from typing import Any

import torch
from gymnasium import spaces
from stable_baselines3 import TD3
from stable_baselines3.td3.policies import Actor, TD3Policy
from torch import Tensor, nn

from leoc.policies.spec import HybridDesign, HybridSpec
from leoc.sb3.common import (
    NORMALISED_LIMIT,
    HybridActorMixin,
    HybridPolicyMixin,
    NetworkOptionsMixin,
    _PaperSettingsMixin,
    hybrid_arguments,
)

__all__ = ["HybridActor", "HybridTD3Policy", "LeocTD3", "LeocTD3Policy"]


class HybridActor(HybridActorMixin, Actor):
    r"""SB3 TD3/DDPG actor whose output is the LEOC blend of an LQR controller and SB3's MLP.

    Output (normalised units, see :mod:`leoc.sb3.common`):
    :math:`\operatorname{clip}_{[-1,1]}(r \tilde G + (1 - r) \tanh(\mathrm{MLP}))`.
    Shapes: observation (B, D) float32 -> normalised action (B, F).

    Parameters
    ----------
    observation_space, action_space, net_arch, features_extractor, features_dim,
    activation_fn, normalize_images
        As for SB3's :class:`stable_baselines3.td3.policies.Actor`. The observation must be a
        flat box (the features are the observation itself) so that ``a`` and ``W`` act on it.
    hybrid_spec : HybridSpec or dict
        The hybrid's choices (:class:`~leoc.policies.HybridSpec`: relevance design and its
        parameters, what the actor loss trains). Its relevance reads the raw observation, so it
        is the same function in normalised and physical units.
    hybrid_design : HybridDesign or dict
        ``W``, ``b`` (physical units), the operating point ``a`` in observation coordinates and
        the relevance design's data (:func:`leoc.policies.hybrid_design`).
    clip_output : bool
        Whether the actor clips its blend to [-1, 1] (default). False: the blend is returned
        unbounded, as TF-Agents' actor network returns ``scale_to_spec(r g + (1 - r) h)``
        (nrjc/LEOC ``DDPG/ddpg.py``), so the actor loss sees the critic beyond the box; the
        executed action is clipped all the same (SB3's collection, :func:`physical_policy`).

    Attributes
    ----------
    hybrid : HybridPolicy
        The blend in normalised units; its ``nonlinear`` is SB3's MLP (ending in tanh).
    physical_gain, physical_bias, operating_obs : Tensor
        float64 buffers with ``W``, ``b`` and ``a`` in physical units (for exact float64
        evaluation, see :func:`leoc.sb3.physical_policy`).
    """

    physical_gain: Tensor
    physical_bias: Tensor
    operating_obs: Tensor

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Box,
        net_arch: list[int],
        features_extractor: nn.Module,
        features_dim: int,
        activation_fn: type[nn.Module] = nn.ReLU,
        normalize_images: bool = True,
        *,
        hybrid_spec: HybridSpec | dict[str, Any],
        hybrid_design: HybridDesign | dict[str, Any],
        clip_output: bool = True,
    ) -> None:
        super().__init__(
            observation_space,
            action_space,
            net_arch,
            features_extractor,
            features_dim,
            activation_fn,
            normalize_images,
        )
        mlp = self.mu
        del self.mu  # the MLP lives on as hybrid.nonlinear (one copy in the state_dict)
        self._init_hybrid(mlp, features_dim, hybrid_spec, hybrid_design)
        self.clip_output = bool(clip_output)

    @property
    def nonlinear(self) -> nn.Module:
        """SB3's MLP, :math:`\\tilde H = \\tanh(\\mathrm{MLP})`, in normalised units."""
        return self.hybrid.nonlinear

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(self.hybrid_constructor_parameters(), clip_output=self.clip_output)
        return data

    def forward(self, obs: Tensor) -> Tensor:
        r"""Normalised action :math:`\operatorname{clip}_{[-1,1]}(r \tilde G + (1-r) \tilde H)`.

        The same function as ``self.hybrid(features)`` (:class:`~leoc.policies.HybridPolicy`
        with ``saturation="clip"``), evaluated with fused kernels because SB3 calls it for
        every environment step (batch 1) and three times per gradient step, where per-op
        overhead dominates: ``addmm`` for :math:`\tilde G`, one matrix-vector product for
        :math:`d = (x - a)^2 \cdot \lambda^{-1}`, and ``lerp(H, G, r)``, which PyTorch
        evaluates as :math:`G - (G - H)(1 - r)` for :math:`r \ge 1/2`, so it returns
        :math:`\tilde G(a)` exactly at :math:`r(a) = 1`.
        """
        features = self.extract_features(obs, self.features_extractor)
        relevance, linear = self.fused_relevance_and_linear(features)
        blend = torch.lerp(self.hybrid.nonlinear(features), linear, relevance)
        if not self.clip_output:
            return blend
        return torch.clamp(blend, -NORMALISED_LIMIT, NORMALISED_LIMIT)


class LeocTD3Policy(NetworkOptionsMixin, TD3Policy):
    r"""SB3's TD3/DDPG policy with the critic layout and network initialisation as options.

    With every option at its default this *is* SB3's ``TD3Policy`` (same modules, same random
    draws, same numbers).

    Parameters
    ----------
    observation_space, action_space, lr_schedule, net_arch, activation_fn, ...
        As for :class:`stable_baselines3.td3.policies.TD3Policy`.
    critic_action_layer, critic_action_units, hidden_init, last_layer_init
        As :class:`NetworkOptionsMixin` describes them; the actor's initialised layers are
        its MLP (the hybrid's nonlinear part).
    """

    def _new_actor(self, features_extractor: nn.Module | None = None) -> Actor:
        return super().make_actor(features_extractor)

    def make_actor(self, features_extractor: nn.Module | None = None) -> Actor:
        """The actor (SB3's, or the hybrid in subclasses), initialised as ``network_options``
        says; SB3 calls this for the actor and its target."""
        actor = self._new_actor(features_extractor)
        self._initialise(actor.nonlinear if isinstance(actor, HybridActor) else actor.mu)
        return actor


class HybridTD3Policy(HybridPolicyMixin, LeocTD3Policy):
    """SB3 TD3/DDPG policy whose actor and target actor are :class:`HybridActor`.

    Use it as ``DDPG(HybridTD3Policy, env, policy_kwargs=hybrid_policy_kwargs(system))`` or
    with ``TD3``. The critics are SB3's (or :class:`SplitCritic`, see :class:`LeocTD3Policy`);
    only the actor changes.

    Parameters
    ----------
    observation_space, action_space, lr_schedule, net_arch, activation_fn, ...
        As for :class:`stable_baselines3.td3.policies.TD3Policy`.
    critic_action_layer, critic_action_units, hidden_init, last_layer_init
        See :class:`LeocTD3Policy`.
    hybrid_spec, hybrid_design, clip_output
        Passed to :class:`HybridActor` (see there); :func:`hybrid_policy_kwargs` builds them
        from a system's LQR design (and, for the ROA relevance, its certificate).
    """

    actor: HybridActor
    hybrid_actor_class = HybridActor
    actor_target: HybridActor

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Box,
        lr_schedule: Any,
        *args: Any,
        clip_output: bool = True,
        **kwargs: Any,
    ) -> None:
        self.hybrid_kwargs = {**hybrid_arguments(kwargs), "clip_output": bool(clip_output)}
        super().__init__(observation_space, action_space, lr_schedule, *args, **kwargs)


class LeocTD3(_PaperSettingsMixin, TD3):
    """SB3 ``TD3`` plus ``actor_learning_rate``, ``target_update_interval``, ``warmup`` and
    ``critic_loss`` (:mod:`leoc.sb3.common`)."""
