r"""What leoc's adapters of Stable-Baselines3's DDPG, TD3 and SAC share.

This module adapts no single SB3 algorithm: it holds what :mod:`leoc.sb3.td3`,
:mod:`leoc.sb3.ddpg` and :mod:`leoc.sb3.sac` (one module per SB3 algorithm) build on,

* the LEOC blend for SB3's off-policy actors, :class:`HybridActorMixin` (mixed into
  :class:`~leoc.sb3.td3.HybridActor` and :class:`~leoc.sb3.sac.HybridSACActor`), its
  constructor keywords (:func:`hybrid_arguments`, :func:`hybrid_policy_kwargs`) and the action
  box (:func:`action_box`);
* the critic layout and the networks' initialisation as options of SB3's twin-critic policies
  (:class:`NetworkOptionsMixin`, :class:`SplitCritic`, :func:`initialise_mlp`);
* the actor's learning rate and warm-up for SB3's off-policy algorithms
  (:class:`ActorRateAndWarmupMixin`), the paper's update settings for SB3's TD3 family
  (``_PaperSettingsMixin``) and the critic loss (:func:`critic_loss_fn`).

Letters: B batch, D observation dimension, F action dimension.

**The hybrid actor.** Inside SB3 an off-policy actor outputs the *normalised* action
:math:`\tilde u \in [-1, 1]^F`, mapped to the physical action by the affine map of the action
box :math:`[u_{low}, u_{high}]`,

.. math::

    u = c + h \odot \tilde u, \qquad c = (u_{high} + u_{low}) / 2, \quad
    h = (u_{high} - u_{low}) / 2

(for a symmetric box :math:`\tilde u = u / u_{max}`). The hybrid actor is the blend of
:class:`leoc.policies.HybridPolicy` in these normalised units,

.. math::

    \tilde\pi(x) = \operatorname{clip}_{[-1, 1]}\big(r(x) \tilde G(x) + (1 - r(x)) \tilde H(x)\big),
    \qquad \tilde G(x) = (W x + b - c) / h, \qquad \tilde H(x) = \tanh(\mathrm{MLP}(x)),

where :math:`\tilde H` is SB3's own actor network (ending in tanh) and the linear part is the
LQR controller :math:`G(x) = W x + b` rescaled by the same affine map. In physical units this is

.. math::

    \pi(x) = c + h \odot \tilde\pi(x)
           = \operatorname{clip}_{[u_{low}, u_{high}]}
             \big(r G + (1 - r) (c + h \odot \tilde H)\big),

a LEOC hybrid with nonlinear part :math:`H = c + h \odot \tanh(\mathrm{MLP})`. The clip is applied
*after* blending and is the identity (value and slope) strictly inside the box, so
:math:`\pi(a) = G(a)` and :math:`\partial\pi/\partial x(a) = W` exactly in physical units whenever
:math:`G(a)` lies strictly inside the box; no tanh acts on the blend.

The affine map only rescales, so no physical quantity is approximated: the relevance
:math:`r(x) = (1 + \sum_i (x_i - a_i)^2 / \lambda_i)^{-2}` is computed on the raw observation.
``W``, ``b`` and ``a`` are buffers, :math:`\lambda = \exp(\text{log\_lambda})` a learnable
parameter (or a frozen buffer); everything is in the model's ``state_dict`` and therefore in
SB3's ``save``/``load``. The target actor is built by the same ``make_actor`` and is a hybrid
too; the soft target update averages ``log_lambda`` along with the MLP weights.

With ``relevance="roa"`` the relevance is :class:`~leoc.policies.ROARelevance` instead: exactly
1 on the LQR's certified region of attraction :math:`\{V \le \rho_{in}\}` (computed on the
state deviation recovered from the observation, so it too is unchanged by the action scaling),
falling to 0 over a band of learnable width ``width_param``. ``P``, :math:`\rho_{in}` and the
observation layout are constructor data (saved with the model); the width is a parameter that
the actor loss trains and the soft update averages. On the flat top ``lerp(H, G, 1)`` returns
:math:`\tilde G` bit for bit, so the actor is the (clipped) LQR there.

**The paper's settings.** Appendix C of Zhang & Capel (2021) uses different Adam step sizes
for the actor (5e-4) and the critic (1e-3), and soft target updates (factor 0.05) every 5
gradient updates. SB3 uses one ``learning_rate`` for both optimisers and updates the targets
after every (actor) update. :class:`~leoc.sb3.ddpg.LeocDDPG` and :class:`~leoc.sb3.td3.LeocTD3`
add exactly these two options and otherwise *are* SB3's algorithms (the training loop is SB3's
own ``train``):

* ``actor_learning_rate``: the actor optimiser's step size (``learning_rate`` stays the
  critic's); ``None`` keeps SB3's behaviour. A learning-rate schedule scales both alike.
* ``target_update_interval``: soft target updates happen on every ``target_update_interval``-th
  of SB3's target-update opportunities (every update for DDPG, every ``policy_delay``-th for
  TD3); in between the Polyak coefficient is set to zero (``polyak`` keeps the nominal one).

A hybrid's ``HybridSpec.relevance_lr_scale`` :math:`s` (DDPG, TD3 and SAC alike) puts the
relevance's parameters (``log_lambda``, or the relevance module's) in a second group of the
actor's Adam, which runs at the actor's rate times :math:`s` (the group key ``"lr_scale"``,
applied after SB3 resets the rates on each ``train`` call); :math:`s = 1` is SB3's single group.

Two further options follow nrjc/LEOC's TF-Agents DDPG (``DDPG/ddpg.py``, ``dao/trainer.py``);
their defaults keep SB3's behaviour bit for bit:

* ``warmup``: ``"uniform"`` (SB3) acts uniformly at random for the first ``learning_starts``
  steps; ``"policy"`` acts with the noisy collect policy from the first step (TF-Agents'
  ``initial_collect_driver`` runs ``agent.collect_policy``). Either way no gradient update
  happens before ``learning_starts`` steps, then one per step (``train_freq=1``).
* ``critic_loss``: ``"mse"`` (SB3: the mean squared TD error) or ``"huber"``,
  the mean Huber loss with delta 1 of TF-Agents' ``td_errors_loss_fn=huber_loss``
  (``tf.compat.v1.losses.huber_loss``: :math:`\tfrac12 e^2` for :math:`|e| \le 1`,
  :math:`|e| - \tfrac12` beyond). With ``"huber"`` the update is :meth:`_train_step`, a
  re-implementation of SB3's TD3 update with only the loss changed (with ``"mse"`` it gives
  SB3's numbers bit for bit; a test checks it).
* ``target_action_clip``: True (SB3) clips the target actor's action to [-1, 1] in the TD
  target; False uses it as it comes, as TF-Agents' DDPG does (``critic_loss`` feeds
  ``target_actor_network``'s output to the target critic unclipped). False also runs
  :meth:`_train_step`.

References
----------
Y. Zhang and F. Capel, "LEOC: A Principled Method in Integrating Reinforcement Learning and
Classical Control Theory", L4DC 2021, eq. 4-5 and appendix C.
T. P. Lillicrap et al., "Continuous control with deep reinforcement learning", ICLR 2016.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from gymnasium import spaces
from stable_baselines3.common.policies import BaseModel
from stable_baselines3.common.preprocessing import get_action_dim
from stable_baselines3.common.torch_layers import create_mlp
from stable_baselines3.common.utils import polyak_update, update_learning_rate
from torch import Tensor, nn

from leoc.policies import HybridPolicy
from leoc.policies.spec import HybridDesign, HybridSpec, build_hybrid, hybrid_design
from leoc.sb3.config import CRITIC_ACTION_UNITS, CRITIC_LOSSES, HIDDEN_INITS, WARMUPS

__all__ = [
    "CRITIC_ACTION_UNITS",
    "CRITIC_LOSSES",
    "HIDDEN_INITS",
    "HUBER_DELTA",
    "LR_SCALE_KEY",
    "WARMUPS",
    "ActorRateAndWarmupMixin",
    "HybridActorMixin",
    "HybridPolicyMixin",
    "NetworkOptionsMixin",
    "SplitCritic",
    "action_box",
    "critic_loss_fn",
    "hybrid_arguments",
    "hybrid_policy_kwargs",
    "initialise_mlp",
    "policy_of",
    "relevance_param_groups",
    "relevance_parameters",
    "scale_group_rates",
]

NORMALISED_LIMIT = 1.0  # SB3's off-policy actors act in [-1, 1]
ACTION_DTYPE = torch.float32  # SB3 actors and replay data are float32
NO_TARGET_UPDATE = 0.0  # Polyak coefficient that leaves the targets unchanged
FULL_PROGRESS = 1.0  # SB3's "progress remaining" at the start of training
HUBER_DELTA = 1.0  # tf.compat.v1.losses.huber_loss's default delta (TF-Agents' DDPG)
#: Key of an optimiser parameter group whose rate is SB3's times its value (the hybrid's
#: relevance group, :func:`relevance_param_groups`).
LR_SCALE_KEY = "lr_scale"


def action_box(action_space: spaces.Box) -> tuple[np.ndarray, np.ndarray]:
    """Centre ``c`` and half-width ``h`` (both (F,), float64) of a bounded action box.

    Raises
    ------
    ValueError
        If the box is unbounded or has a non-positive width.
    """
    low = np.asarray(action_space.low, dtype=np.float64).reshape(-1)
    high = np.asarray(action_space.high, dtype=np.float64).reshape(-1)
    if not (np.all(np.isfinite(low)) and np.all(np.isfinite(high)) and np.all(high > low)):
        raise ValueError(
            f"action_space: expected a bounded box with high > low, found low={low.tolist()}, "
            f"high={high.tolist()}"
        )
    return 0.5 * (high + low), 0.5 * (high - low)


class HybridActorMixin:
    r"""The LEOC blend in SB3's normalised action units, shared by the DDPG/TD3 and SAC actors.

    A hybrid actor class derives from this mixin and from an SB3 actor class, builds the SB3
    actor, takes its network :math:`\tilde H` (normalised units, bounded by tanh) out of it and
    calls :meth:`_init_hybrid`, which holds, for every hybrid actor alike, the linear part
    :math:`\tilde G(x) = (W x + b - c) / h`, the relevance (the paper's, its precision
    parametrisation, or the ROA relevance) and the blend :class:`~leoc.policies.HybridPolicy`
    (clip saturation to :math:`[-1, 1]`). See the module docstring for the units and the
    identities; :class:`~leoc.sb3.td3.HybridActor` (DDPG/TD3) and
    :class:`~leoc.sb3.sac.HybridSACActor` (SAC) differ only in what they do with the blend.

    Attributes
    ----------
    hybrid : HybridPolicy
        The blend in normalised units; its ``nonlinear`` is :math:`\tilde H`.
    physical_gain, physical_bias, operating_obs : Tensor
        float64 buffers with ``W``, ``b`` and ``a`` in physical units (for exact float64
        evaluation, see :func:`leoc.sb3.physical_policy`).
    hybrid_spec : HybridSpec
        The choices that made the hybrid (relevance design, its parameters, what is learned).
    hybrid_design : HybridDesign
        ``W``, ``b``, ``a`` and the relevance design's data, in physical units.
    """

    hybrid: HybridPolicy
    hybrid_spec: HybridSpec
    hybrid_design: HybridDesign
    physical_gain: Tensor
    physical_bias: Tensor
    operating_obs: Tensor
    action_space: spaces.Box
    features_extractor: nn.Module

    def _init_hybrid(
        self, nonlinear: nn.Module, features_dim: int, spec: object, design: object
    ) -> None:
        """Build ``self.hybrid`` around ``nonlinear`` (:math:`\tilde H`, (B, D) -> (B, F)) by
        :func:`leoc.policies.build_hybrid` in normalised units, and register the physical-units
        buffers. ``spec`` and ``design``: a :class:`~leoc.policies.HybridSpec` and a
        :class:`~leoc.policies.HybridDesign` or their dicts (what SB3 saves)."""
        spec = spec if isinstance(spec, HybridSpec) else HybridSpec.from_dict(spec)  # type: ignore[arg-type]
        if not isinstance(design, HybridDesign):
            design = HybridDesign.from_dict(design)  # type: ignore[arg-type]
        act_dim = int(np.prod(self.action_space.shape))
        found = (len(design.bias), len(design.operating_obs))
        if found != (act_dim, features_dim):
            raise ValueError(
                f"hybrid_design: expected an action of size F = {act_dim} and an observation of "
                f"size D = {features_dim} (the spaces), found (F, D) = {found}"
            )
        self.hybrid_spec = spec
        self.hybrid_design = design
        gain = torch.as_tensor(np.asarray(design.gain, dtype=np.float64))
        bias = torch.as_tensor(np.asarray(design.bias, dtype=np.float64))
        point = torch.as_tensor(np.asarray(design.operating_obs, dtype=np.float64))
        self.register_buffer("physical_gain", gain)  # type: ignore[attr-defined]
        self.register_buffer("physical_bias", bias)  # type: ignore[attr-defined]
        self.register_buffer("operating_obs", point)  # type: ignore[attr-defined]
        self.hybrid = build_hybrid(
            spec,
            design,
            nonlinear,
            action_limit=NORMALISED_LIMIT,
            saturation="clip",
            action_box=action_box(self.action_space),
            dtype=ACTION_DTYPE,
        )

    def hybrid_constructor_parameters(self) -> dict[str, Any]:
        """The hybrid's constructor arguments (what SB3 saves to rebuild the actor)."""
        return {
            "hybrid_spec": self.hybrid_spec.to_dict(),
            "hybrid_design": self.hybrid_design.to_dict(),
        }

    def fused_relevance_and_linear(self, features: Tensor) -> tuple[Tensor, Tensor]:
        r"""Relevance :math:`r` (B, 1) and normalised linear part :math:`\tilde G` (B, F).

        The same values as ``self.hybrid.relevance`` and ``self.hybrid.linear``, evaluated with
        fused kernels because SB3 calls the actor for every environment step (batch 1) and
        several times per gradient step, where per-op overhead dominates: one matrix-vector
        product for :math:`d = (x - a)^2 \cdot \lambda^{-1}` and ``addmm`` for
        :math:`\tilde G`. An ROA relevance is exactly 1 on its flat top.
        """
        hybrid = self.hybrid
        if hybrid.relevance_module is None:
            offset = features - hybrid.operating_point
            distance = offset.square() @ torch.exp(-hybrid.log_lambda)  # (B,)
            relevance = torch.reciprocal(torch.square(distance + 1.0)).unsqueeze(-1)  # (B, 1)
        else:  # ROA: exactly 1 on the flat top, where lerp returns G bit for bit; or precision
            relevance = hybrid.relevance_module(features)  # (B, 1)
        linear = torch.addmm(hybrid.linear.b, features, hybrid.linear.W.T)  # (B, F)
        return relevance, linear

    def relevance(self, obs: Tensor) -> Tensor:
        """Relevance :math:`r(x)` of the linear part, shape (B, 1)."""
        features = self.extract_features(obs, self.features_extractor)  # type: ignore[attr-defined]
        return self.hybrid.relevance(features)


def initialise_mlp(module: nn.Module, hidden_init: str, last_layer_init: float | None) -> None:
    r"""Re-initialise the ``nn.Linear`` layers of ``module`` in place (the last one is the output).

    ``hidden_init="torch"`` keeps PyTorch's defaults (weights and biases
    :math:`U(\pm 1/\sqrt{n_{in}})`); ``"tf_agents"`` is TF-Agents' DDPG networks' default
    (``tf_agents/agents/ddpg/actor_network.py``, ``critic_network.py``: Keras
    ``VarianceScaling(scale=1/3, mode="fan_in", distribution="uniform")``, whose limit is
    :math:`\sqrt{3 \cdot \tfrac13 / n_{in}} = 1/\sqrt{n_{in}}`, and Keras' zero biases) for every
    layer. ``last_layer_init=v`` then sets the output layer's weights to :math:`U(\pm v)` and its
    bias to 0 (TF-Agents' ``RandomUniform(-0.003, 0.003)`` for ``v = 0.003``); ``None`` leaves
    it as the hidden layers are.
    """
    if hidden_init not in HIDDEN_INITS:
        raise ValueError(f"hidden_init: expected one of {HIDDEN_INITS}, found {hidden_init!r}")
    linears = [layer for layer in module.modules() if isinstance(layer, nn.Linear)]
    with torch.no_grad():
        if hidden_init == "tf_agents":
            for layer in linears:
                bound = 1.0 / math.sqrt(layer.in_features)
                layer.weight.uniform_(-bound, bound)
                layer.bias.zero_()
        if last_layer_init is not None and linears:
            linears[-1].weight.uniform_(-last_layer_init, last_layer_init)
            linears[-1].bias.zero_()


class _SplitQNetwork(nn.Module):
    """``tail(cat(head(features), action))``: one Q network of :class:`SplitCritic`."""

    def __init__(self, head: nn.Module, tail: nn.Module) -> None:
        super().__init__()
        self.head = head
        self.tail = tail

    def forward(self, features: Tensor, actions: Tensor) -> Tensor:
        return self.tail(torch.cat([self.head(features), actions], dim=1))


class SplitCritic(BaseModel):
    r"""Q(s, a) whose action joins after ``action_layer`` hidden layers, in chosen units.

    For ``net_arch = [n_1, ..., n_k]`` and ``action_layer = j``: the features go through
    :math:`n_1, ..., n_j` (ReLU), the action is concatenated, then :math:`n_{j+1}, ..., n_k`
    (ReLU) and a linear output. TF-Agents' DDPG critic as nrjc/LEOC configures it
    (``DDPG/ddpg.py``: ``observation_fc_layer_params=(400,)``, ``joint_fc_layer_params=(300,)``)
    is ``[400, 300]`` with ``j = 1``: obs -> 400 -> concat(action) -> 300 -> 1. With
    ``action_units="physical"`` the critic sees :math:`c + h \odot \tilde u` (TF-Agents feeds
    the action in the action spec's units), else SB3's normalised :math:`\tilde u`.
    Same interface as SB3's ``ContinuousCritic`` (``forward`` -> tuple of (B, 1), ``q1_forward``).
    """

    features_extractor: nn.Module
    action_centre: Tensor
    action_half_width: Tensor

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Box,
        net_arch: list[int],
        features_extractor: nn.Module,
        features_dim: int,
        activation_fn: type[nn.Module] = nn.ReLU,
        normalize_images: bool = True,
        n_critics: int = 2,
        share_features_extractor: bool = True,
        *,
        action_layer: int = 1,
        action_units: str = "physical",
    ) -> None:
        super().__init__(
            observation_space,
            action_space,
            features_extractor=features_extractor,
            normalize_images=normalize_images,
        )
        _check_critic_options(action_layer, action_units, net_arch)
        action_dim = get_action_dim(action_space)
        centre, half = action_box(action_space)
        if action_units == "normalised":  # the identity map
            centre, half = np.zeros_like(centre), np.ones_like(half)
        self.register_buffer("action_centre", torch.as_tensor(centre, dtype=ACTION_DTYPE))
        self.register_buffer("action_half_width", torch.as_tensor(half, dtype=ACTION_DTYPE))
        self.share_features_extractor = share_features_extractor
        self.n_critics = n_critics
        joint_in = net_arch[action_layer - 1] if action_layer > 0 else features_dim
        self.q_networks: list[nn.Module] = []
        for index in range(n_critics):
            head = nn.Sequential(
                *create_mlp(features_dim, -1, net_arch[:action_layer], activation_fn)
            )
            tail = nn.Sequential(
                *create_mlp(joint_in + action_dim, 1, net_arch[action_layer:], activation_fn)
            )
            q_net = _SplitQNetwork(head, tail)
            self.add_module(f"qf{index}", q_net)
            self.q_networks.append(q_net)

    def _actions(self, actions: Tensor) -> Tensor:
        return self.action_centre + self.action_half_width * actions

    def forward(self, obs: Tensor, actions: Tensor) -> tuple[Tensor, ...]:
        with torch.set_grad_enabled(not self.share_features_extractor):
            features = self.extract_features(obs, self.features_extractor)
        units = self._actions(actions)
        return tuple(q_net(features, units) for q_net in self.q_networks)

    def q1_forward(self, obs: Tensor, actions: Tensor) -> Tensor:
        """Q-value ``(B, 1)`` of the first critic only, the features without gradient (as SB3's
        ``q1_forward``, which the actor loss uses)."""
        with torch.no_grad():
            features = self.extract_features(obs, self.features_extractor)
        return self.q_networks[0](features, self._actions(actions))


def _check_critic_options(
    action_layer: object, action_units: object, net_arch: Sequence[int]
) -> None:
    if isinstance(action_layer, bool) or not isinstance(action_layer, int):
        raise ValueError(f"critic_action_layer: expected an int, found {action_layer!r}")
    if not 0 <= action_layer <= len(net_arch):
        raise ValueError(
            f"critic_action_layer: expected 0 <= layer <= {len(net_arch)} (the critic's hidden "
            f"layers {list(net_arch)}), found {action_layer}"
        )
    if action_units not in CRITIC_ACTION_UNITS:
        raise ValueError(
            f"critic_action_units: expected one of {CRITIC_ACTION_UNITS}, found {action_units!r}"
        )


class NetworkOptionsMixin:
    r"""The critic layout and the networks' initialisation as options of an SB3 policy with
    twin critics (TD3/DDPG's and SAC's); mixed in before the SB3 policy class.

    Options (keywords of the policy; all at their defaults, the policy is SB3's own, bit for
    bit):

    critic_action_layer : int
        Hidden layers of the critic before the action joins: 0 (SB3: concatenated to the
        observation) or ``j >= 1`` (:class:`SplitCritic`; TF-Agents' DDPG critic: 1).
    critic_action_units : {"normalised", "physical"}
        Units of the action the critic sees (SB3: normalised; TF-Agents: physical).
    hidden_init : {"torch", "tf_agents"}
        Initialisation of the actor's and critics' layers (:func:`initialise_mlp`).
    last_layer_init : float, optional
        Output layers' weights :math:`U(\pm v)`, zero bias (TF-Agents: 0.003); None: as
        ``hidden_init``.
    """

    network_options: dict[str, Any]
    critic_kwargs: dict[str, Any]
    device: Any

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Box,
        lr_schedule: Any,
        *args: Any,
        critic_action_layer: int = 0,
        critic_action_units: str = "normalised",
        hidden_init: str = "torch",
        last_layer_init: float | None = None,
        **kwargs: Any,
    ) -> None:
        if hidden_init not in HIDDEN_INITS:
            raise ValueError(f"hidden_init: expected one of {HIDDEN_INITS}, found {hidden_init!r}")
        if last_layer_init is not None and not (
            isinstance(last_layer_init, (int, float)) and last_layer_init > 0
        ):
            raise ValueError(
                f"last_layer_init: expected a positive number or None, found {last_layer_init!r}"
            )
        self.network_options = {
            "critic_action_layer": critic_action_layer,
            "critic_action_units": critic_action_units,
            "hidden_init": hidden_init,
            "last_layer_init": None if last_layer_init is None else float(last_layer_init),
        }
        # the SB3 policy after this mixin in the MRO builds the networks (make_actor/critic)
        super().__init__(observation_space, action_space, lr_schedule, *args, **kwargs)  # type: ignore[call-arg]

    def _initialise(self, module: nn.Module) -> None:
        options = self.network_options
        if (options["hidden_init"], options["last_layer_init"]) != ("torch", None):
            initialise_mlp(module, options["hidden_init"], options["last_layer_init"])

    def make_critic(self, features_extractor: nn.Module | None = None) -> nn.Module:
        """SB3's critic, or a :class:`SplitCritic` when the action joins later or in physical
        units (``network_options``), initialised as ``network_options`` says."""
        layer = self.network_options["critic_action_layer"]
        units = self.network_options["critic_action_units"]
        _check_critic_options(layer, units, self.critic_kwargs["net_arch"])
        if (layer, units) == (0, "normalised"):
            critic = super().make_critic(features_extractor)  # type: ignore[misc]
        else:
            critic_kwargs = self._update_features_extractor(self.critic_kwargs, features_extractor)  # type: ignore[attr-defined]
            critic = SplitCritic(**critic_kwargs, action_layer=layer, action_units=units)
            critic = critic.to(self.device)
        for q_net in critic.q_networks:
            self._initialise(q_net)
        return critic

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()  # type: ignore[misc]
        data.update(self.network_options)
        return data


#: Constructor keywords of the hybrid actors before :class:`~leoc.policies.HybridSpec` (models
#: saved by leoc 0.1 until November 2026), read by :func:`hybrid_arguments` so they still load.
LEGACY_HYBRID_KEYWORDS = (
    "lqr_gain",
    "lqr_bias",
    "operating_obs",
    "lambda_init",
    "learn_lambda",
    "relevance",
    "relevance_parametrisation",
    "roa_obs_layout",
    "roa_operating_state",
    "roa_lyapunov_matrix",
    "roa_rho_in",
    "roa_width_init",
    "learn_width",
)


def _from_legacy_keywords(old: dict[str, Any]) -> dict[str, Any]:
    """``hybrid_spec``/``hybrid_design`` dicts of a model saved with the keywords of
    :data:`LEGACY_HYBRID_KEYWORDS` (the resolved ROA level is kept as it was saved)."""
    spec = {
        key: old[key]
        for key in ("lambda_init", "learn_lambda", "relevance", "relevance_parametrisation")
        if key in old
    }
    data = {}
    if old.get("relevance") == "roa":
        spec.update(width_init=old["roa_width_init"], learn_width=old["learn_width"])
        data = {
            "obs_layout": old["roa_obs_layout"],
            "operating_state": old["roa_operating_state"],
            "lyapunov_matrix": old["roa_lyapunov_matrix"],
            "rho_in": old["roa_rho_in"],
        }
    design = {
        "gain": old["lqr_gain"],
        "bias": old["lqr_bias"],
        "operating_obs": old["operating_obs"],
        "relevance_data": data,
    }
    return {"hybrid_spec": HybridSpec.from_dict(spec).to_dict(), "hybrid_design": design}


def hybrid_arguments(policy_kwargs: dict[str, Any]) -> dict[str, Any]:
    """The hybrid actor's keywords (``hybrid_spec``, ``hybrid_design``, JSON-friendly dicts),
    *popped* from a hybrid policy's keywords (what is left there is the SB3 policy's own).

    Models saved before :class:`~leoc.policies.HybridSpec` existed give the keywords of
    :data:`LEGACY_HYBRID_KEYWORDS` instead; they are converted.

    Raises
    ------
    ValueError
        If neither ``hybrid_spec`` and ``hybrid_design`` nor the legacy keywords are given.
    """
    legacy = {key: policy_kwargs.pop(key) for key in LEGACY_HYBRID_KEYWORDS if key in policy_kwargs}
    if legacy and "hybrid_spec" in policy_kwargs:
        raise ValueError(
            f"policy_kwargs: {sorted(legacy)} belong in hybrid_spec or hybrid_design "
            "(leoc.policies.HybridSpec, HybridDesign); found them beside hybrid_spec"
        )
    if legacy:
        return _from_legacy_keywords(legacy)
    missing = [key for key in ("hybrid_spec", "hybrid_design") if key not in policy_kwargs]
    if missing:
        raise ValueError(
            f"policy_kwargs: a hybrid policy needs {', '.join(missing)} "
            "(leoc.sb3.hybrid_policy_kwargs builds them from a system); found none"
        )
    spec, design = policy_kwargs.pop("hybrid_spec"), policy_kwargs.pop("hybrid_design")
    return {
        "hybrid_spec": spec.to_dict() if isinstance(spec, HybridSpec) else dict(spec),
        "hybrid_design": design.to_dict() if isinstance(design, HybridDesign) else dict(design),
    }


def hybrid_policy_kwargs(
    system: Any,
    spec: HybridSpec | None = None,
    lqr_method: str = "discrete",
    clip_output: bool = True,
    **extra: Any,
) -> dict[str, Any]:
    r"""``policy_kwargs`` of :class:`~leoc.sb3.td3.HybridTD3Policy` (and
    :class:`~leoc.sb3.sac.HybridSACPolicy`) from a system's LQR design.

    Parameters
    ----------
    system : leoc.systems.System or str
        The system (or its name); ``W, b`` come from :func:`leoc.control.design_lqr` and ``a``
        is ``system.operating_obs``.
    spec : HybridSpec, optional
        The hybrid's choices; default :class:`~leoc.policies.HybridSpec` (the paper's
        relevance, :math:`\Lambda = I` learned).
    lqr_method : {"discrete", "continuous", "authors"}
        LQR design method.
    clip_output : bool
        See :class:`~leoc.sb3.td3.HybridActor`.
    **extra
        Further policy kwargs (``net_arch``, ...). Keywords that name a
        :class:`~leoc.policies.HybridSpec` field (``relevance="roa"``, ``learn_lambda=False``)
        change ``spec`` (a shorthand for ``spec.replace(...)``).
    """
    from leoc.control import design_lqr
    from leoc.systems import make_system

    if isinstance(system, str):
        system = make_system(system)
    changes = {key: extra.pop(key) for key in HybridSpec.field_names() if key in extra}
    spec = (spec or HybridSpec()).replace(**changes)
    design = design_lqr(system, method=lqr_method)  # type: ignore[arg-type]
    return {
        "hybrid_spec": spec.to_dict(),
        "hybrid_design": hybrid_design(spec, system, design).to_dict(),
        "clip_output": clip_output,
        **extra,
    }


def critic_loss_fn(name: str) -> Any:
    """The elementwise-mean TD loss ``loss(q, target)`` called ``name`` (see the module)."""
    if name not in CRITIC_LOSSES:
        raise ValueError(f"critic_loss: expected one of {CRITIC_LOSSES}, found {name!r}")
    if name == "huber":
        return lambda q, target: F.huber_loss(q, target, delta=HUBER_DELTA)
    return F.mse_loss


def relevance_parameters(hybrid: HybridPolicy) -> list[nn.Parameter]:
    """The relevance's parameters: the paper relevance's ``log_lambda`` when it is learned
    (a Parameter on the :class:`~leoc.policies.HybridPolicy` itself), else those of its
    ``relevance_module`` (none for a frozen paper relevance)."""
    if hybrid.relevance_module is not None:
        return list(hybrid.relevance_module.parameters())
    log_lambda = hybrid.log_lambda
    return [log_lambda] if isinstance(log_lambda, nn.Parameter) else []


def relevance_param_groups(actor: nn.Module, learning_rate: float) -> list[dict[str, Any]] | None:
    """The hybrid actor's optimiser groups for its spec's ``relevance_lr_scale`` ``s``:
    everything but the relevance (at ``learning_rate``), then the relevance's parameters (at
    ``learning_rate * s``, the group key :data:`LR_SCALE_KEY` holding ``s``). None, SB3's single
    group, when ``s == 1`` or the relevance has no parameters."""
    scale = float(actor.hybrid_spec.relevance_lr_scale)  # type: ignore[union-attr]
    own = relevance_parameters(actor.hybrid)  # type: ignore[arg-type]
    if scale == 1.0 or not own:
        return None
    own_ids = {id(parameter) for parameter in own}
    rest = [parameter for parameter in actor.parameters() if id(parameter) not in own_ids]
    return [
        {"params": rest},
        {"params": own, "lr": learning_rate * scale, LR_SCALE_KEY: scale},
    ]


def scale_group_rates(optimizers: Sequence[torch.optim.Optimizer]) -> None:
    """Multiply the learning rate of every parameter group that has :data:`LR_SCALE_KEY` by it
    (once per optimiser, however often it is listed); to follow SB3's resetting every group to
    one rate."""
    unique = {id(optimizer): optimizer for optimizer in optimizers}
    for optimizer in unique.values():
        for group in optimizer.param_groups:
            if LR_SCALE_KEY in group:
                group["lr"] = group["lr"] * group[LR_SCALE_KEY]


class ActorRateAndWarmupMixin:
    """``actor_learning_rate`` and ``warmup`` for any SB3 off-policy algorithm with an actor.

    Shared by :class:`~leoc.sb3.ddpg.LeocDDPG`, :class:`~leoc.sb3.td3.LeocTD3` and
    :class:`~leoc.sb3.sac.LeocSAC`; see the module docstring for the two options. The class
    that mixes it in sets both attributes (through :meth:`_init_actor_rate_and_warmup`) before
    SB3 uses them.
    """

    actor_learning_rate: float | None
    warmup: str

    def _init_actor_rate_and_warmup(self, actor_learning_rate: float | None, warmup: str) -> None:
        """Validate and set the two options (ValueError naming the argument)."""
        if warmup not in WARMUPS:
            raise ValueError(f"warmup: expected one of {WARMUPS}, found {warmup!r}")
        if actor_learning_rate is not None and not actor_learning_rate > 0:
            raise ValueError(f"actor_learning_rate: expected > 0, found {actor_learning_rate}")
        self.warmup = warmup
        self.actor_learning_rate = actor_learning_rate

    def _update_learning_rate(
        self, optimizers: list[torch.optim.Optimizer] | torch.optim.Optimizer
    ) -> None:
        """SB3's (every group of ``optimizers`` at the schedule's rate), then the actor's own
        rate (``actor_learning_rate``), then each group's ``lr_scale`` (the hybrid's relevance
        group, :func:`relevance_param_groups`) applied to the rate just set."""
        super()._update_learning_rate(optimizers)  # type: ignore[misc]
        reset = list(optimizers) if isinstance(optimizers, list) else [optimizers]
        if getattr(self, "actor_learning_rate", None) is not None:
            schedule = self.lr_schedule  # type: ignore[attr-defined]
            ratio = schedule(self._current_progress_remaining) / schedule(FULL_PROGRESS)  # type: ignore[attr-defined]
            update_learning_rate(self.actor.optimizer, self.actor_learning_rate * ratio)  # type: ignore[attr-defined,operator]
            reset.append(self.actor.optimizer)  # type: ignore[attr-defined]
        scale_group_rates(reset)

    def _sample_action(
        self, learning_starts: int, action_noise: Any = None, n_envs: int = 1
    ) -> tuple[np.ndarray, np.ndarray]:
        # warmup="policy": the noisy policy acts from the first step (no uniform phase); the
        # updates still wait for learning_starts (SB3's learn loop checks it on its own).
        starts = 0 if getattr(self, "warmup", "uniform") == "policy" else learning_starts
        return super()._sample_action(starts, action_noise, n_envs)  # type: ignore[misc]


class _PaperSettingsMixin(ActorRateAndWarmupMixin):
    """Separate actor learning rate and target update interval for SB3's TD3 family."""

    target_update_interval: int
    polyak: float

    def __init__(
        self,
        *args: Any,
        actor_learning_rate: float | None = None,
        target_update_interval: int = 1,
        warmup: str = "uniform",
        critic_loss: str = "mse",
        target_action_clip: bool = True,
        **kwargs: Any,
    ) -> None:
        if warmup not in WARMUPS:
            raise ValueError(f"warmup: expected one of {WARMUPS}, found {warmup!r}")
        critic_loss_fn(critic_loss)  # validates the name
        self.warmup = warmup
        self.critic_loss = critic_loss
        self.target_action_clip = bool(target_action_clip)
        super().__init__(*args, **kwargs)  # the SB3 algorithm after this mixin in the MRO
        self._init_paper_settings(actor_learning_rate, target_update_interval)

    def _init_paper_settings(
        self, actor_learning_rate: float | None, target_update_interval: int
    ) -> None:
        self._init_actor_rate_and_warmup(actor_learning_rate, self.warmup)
        if isinstance(target_update_interval, bool) or not (
            isinstance(target_update_interval, int) and target_update_interval >= 1
        ):
            raise ValueError(
                f"target_update_interval: expected an int >= 1, found {target_update_interval!r}"
            )
        self.target_update_interval = target_update_interval
        self.polyak = float(self.tau)  # type: ignore[attr-defined]

    def _train_calls(self, gradient_steps: int, batch_size: int) -> None:
        """SB3's own update (MSE loss, clipped target actions), else :meth:`_train_step`."""
        own = getattr(self, "critic_loss", "mse") != "mse" or not getattr(
            self, "target_action_clip", True
        )
        if not own:
            super().train(gradient_steps, batch_size)  # type: ignore[misc]
            return
        self.policy.set_training_mode(True)  # type: ignore[attr-defined]
        self._update_learning_rate([self.actor.optimizer, self.critic.optimizer])  # type: ignore[attr-defined]
        for _ in range(gradient_steps):
            self._train_step(batch_size, critic_loss_fn(self.critic_loss))

    def _train_step(self, batch_size: int, loss_fn: Any) -> None:
        r"""One TD3/DDPG gradient step as SB3's ``TD3.train``, with the critic loss ``loss_fn``.

        Target: :math:`y = r + (1 - done)\,\gamma \min_k Q'_k(s', \operatorname{clip}(
        \mu'(s') + \epsilon))` (no clip with ``target_action_clip=False``), :math:`\epsilon`
        clipped Gaussian smoothing noise (zero std for
        DDPG); critic loss :math:`\sum_k \mathrm{loss}(Q_k(s, a), y)`; every ``policy_delay``
        updates the actor loss :math:`-\mathrm{mean}\, Q_1(s, \mu(s))` and the soft target
        updates with coefficient ``tau``.
        """
        self._n_updates += 1  # type: ignore[has-type]
        data = self.replay_buffer.sample(batch_size, env=self._vec_normalize_env)  # type: ignore[attr-defined]
        discounts = data.discounts if data.discounts is not None else self.gamma  # type: ignore[attr-defined]
        with torch.no_grad():
            noise = data.actions.clone().data.normal_(0, self.target_policy_noise)  # type: ignore[attr-defined]
            noise = noise.clamp(-self.target_noise_clip, self.target_noise_clip)  # type: ignore[attr-defined]
            next_actions = self.actor_target(data.next_observations) + noise  # type: ignore[attr-defined]
            if self.target_action_clip:
                next_actions = next_actions.clamp(-NORMALISED_LIMIT, NORMALISED_LIMIT)
            next_q = torch.cat(self.critic_target(data.next_observations, next_actions), dim=1)  # type: ignore[attr-defined]
            next_q, _ = torch.min(next_q, dim=1, keepdim=True)
            target_q = data.rewards + (1 - data.dones) * discounts * next_q
        current_q = self.critic(data.observations, data.actions)  # type: ignore[attr-defined]
        critic_loss = sum(loss_fn(q, target_q) for q in current_q)
        self.critic.optimizer.zero_grad()  # type: ignore[attr-defined]
        critic_loss.backward()  # type: ignore[union-attr]
        self.critic.optimizer.step()  # type: ignore[attr-defined]
        if self._n_updates % self.policy_delay == 0:  # type: ignore[attr-defined]
            actor = self.actor  # type: ignore[attr-defined]
            actor_loss = -self.critic.q1_forward(data.observations, actor(data.observations)).mean()  # type: ignore[attr-defined]
            actor.optimizer.zero_grad()
            actor_loss.backward()
            actor.optimizer.step()
            polyak_update(self.critic.parameters(), self.critic_target.parameters(), self.tau)  # type: ignore[attr-defined]
            polyak_update(actor.parameters(), self.actor_target.parameters(), self.tau)  # type: ignore[attr-defined]
            polyak_update(self.critic_batch_norm_stats, self.critic_batch_norm_stats_target, 1.0)  # type: ignore[attr-defined]
            polyak_update(self.actor_batch_norm_stats, self.actor_batch_norm_stats_target, 1.0)  # type: ignore[attr-defined]

    def train(self, gradient_steps: int, batch_size: int = 100) -> None:
        if self.target_update_interval == 1:
            self._train_calls(gradient_steps, batch_size)
            return
        delay = int(getattr(self, "policy_delay", 1))
        for _ in range(gradient_steps):
            # SB3 counts the update first, then updates actor and targets when it divides by
            # policy_delay; we keep every target_update_interval-th of those opportunities.
            update = self._n_updates + 1  # type: ignore[attr-defined]
            opportunity = update % delay == 0
            due = opportunity and (update // delay) % self.target_update_interval == 0
            self.tau = self.polyak if due else NO_TARGET_UPDATE
            self._train_calls(1, batch_size)
        self.tau = self.polyak


def policy_of(
    config: Any,
    env: Any,
    baseline: type,
    hybrid: type,
    hybrid_kwargs: dict[str, Any] | None = None,
) -> tuple[type, dict[str, Any]]:
    """The SB3 policy class of a :class:`~leoc.sb3.DDPGConfig` and its ``policy_kwargs``:
    ``baseline`` with the config's networks, or, for a hybrid config, ``hybrid`` with the
    hybrid's keywords from the LQR of ``env``'s system (:func:`hybrid_policy_kwargs`), or
    ``hybrid_kwargs`` (``hybrid_spec`` and ``hybrid_design`` dicts) where the caller designed
    them (a gymnasium env has no leoc system: :func:`leoc.sb3.train_gym`)."""
    policy_kwargs: dict[str, Any] = {
        "net_arch": {"pi": list(config.actor_hidden), "qf": list(config.critic_hidden)},
        **config.network_kwargs(),
    }
    if not config.hybrid:
        return baseline, policy_kwargs
    if hybrid_kwargs is not None:
        clip = {"clip_output": config.actor_output_clip}
        return hybrid, {**hybrid_kwargs, **clip, **policy_kwargs}
    system = env.unwrapped.system
    keywords = hybrid_policy_kwargs(
        system,
        config.hybrid,
        config.lqr_method,
        clip_output=config.actor_output_clip,  # True for SAC (a TD3-family field)
        **policy_kwargs,
    )
    return hybrid, keywords


class HybridPolicyMixin:
    """What a hybrid SB3 policy adds to its algorithm's policy: its actor is
    ``hybrid_actor_class`` built with ``hybrid_kwargs`` (the hybrid's keywords, which SB3 saves
    with the model), and, for a spec with ``relevance_lr_scale != 1``, an actor optimiser with
    the relevance in a group of its own (:func:`relevance_param_groups`). Mixed in before the
    policy class; the subclass sets both.

    SB3 sets every group of an optimiser to one rate on each ``train`` call; leoc's learners
    (:class:`ActorRateAndWarmupMixin`: :class:`~leoc.sb3.LeocDDPG`, :class:`~leoc.sb3.LeocTD3`,
    :class:`~leoc.sb3.LeocSAC`) then scale the relevance's group. Under SB3's own ``DDPG``,
    ``TD3`` or ``SAC`` the group runs at the actor's rate from the first update on."""

    hybrid_actor_class: type
    hybrid_kwargs: dict[str, Any]
    actor_kwargs: dict[str, Any]
    device: Any

    def _new_actor(self, features_extractor: nn.Module | None = None) -> nn.Module:
        actor_kwargs = self._update_features_extractor(self.actor_kwargs, features_extractor)  # type: ignore[attr-defined]
        return self.hybrid_actor_class(**actor_kwargs, **self.hybrid_kwargs).to(self.device)

    def _build(self, lr_schedule: Any) -> None:
        """SB3's networks and optimisers; then, for a spec with ``relevance_lr_scale != 1``,
        the actor's optimiser rebuilt with the relevance's parameters in a group of their own
        (:func:`relevance_param_groups`). Scale 1 leaves SB3's optimiser as it is."""
        super()._build(lr_schedule)  # type: ignore[misc]
        groups = relevance_param_groups(self.actor, lr_schedule(FULL_PROGRESS))  # type: ignore[attr-defined]
        if groups is not None:
            self.actor.optimizer = self.optimizer_class(  # type: ignore[attr-defined]
                groups,
                lr=lr_schedule(FULL_PROGRESS),
                **self.optimizer_kwargs,  # type: ignore[attr-defined]
            )

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()  # type: ignore[misc]
        data.update(self.hybrid_kwargs)
        return data
