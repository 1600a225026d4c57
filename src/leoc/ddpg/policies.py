r"""LEOC hybrid actor and policy classes for Stable-Baselines3's DDPG and TD3.

Letters: B batch, D observation dimension, F action dimension.

Inside SB3 an off-policy actor outputs the *normalised* action :math:`\tilde u \in [-1, 1]^F`,
mapped to the physical action by the affine map of the action box :math:`[u_{low}, u_{high}]`,

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

References
----------
Y. Zhang and F. Capel, "LEOC: A Principled Method in Integrating Reinforcement Learning and
Classical Control Theory", L4DC 2021, eq. 4-5.
T. P. Lillicrap et al., "Continuous control with deep reinforcement learning", ICLR 2016.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.policies import BaseModel
from stable_baselines3.common.preprocessing import get_action_dim
from stable_baselines3.common.torch_layers import create_mlp
from stable_baselines3.td3.policies import Actor, TD3Policy
from torch import Tensor, nn

from leoc.ddpg.config import CRITIC_ACTION_UNITS, HIDDEN_INITS
from leoc.policies import HybridPolicy, LinearController, PrecisionRelevance, ROARelevance
from leoc.policies.relevance import (
    DEFAULT_ROA_WIDTH,
    RELEVANCE_KINDS,
    RELEVANCE_PARAMETRISATIONS,
)

__all__ = [
    "CRITIC_ACTION_UNITS",
    "ROA_KWARG_NAMES",
    "HIDDEN_INITS",
    "HybridActor",
    "HybridActorMixin",
    "HybridDDPGPolicy",
    "HybridTD3Policy",
    "LeocTD3Policy",
    "NetworkOptionsMixin",
    "SplitCritic",
    "action_box",
    "check_hybrid_options",
    "hybrid_actor_kwargs",
    "hybrid_policy_kwargs",
    "initialise_mlp",
    "roa_relevance_kwargs",
]

NORMALISED_LIMIT = 1.0  # SB3's off-policy actors act in [-1, 1]
ACTION_DTYPE = torch.float32  # SB3 actors and replay data are float32


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


def _as_matrix(value: object, name: str, shape: tuple[int, ...]) -> np.ndarray:
    array = np.asarray(value, dtype=np.float64)
    if array.shape != shape or not np.all(np.isfinite(array)):
        raise ValueError(f"{name}: expected finite numbers of shape {shape}, found {array!r}")
    return array


def check_hybrid_options(relevance: object, relevance_parametrisation: object) -> None:
    """Check a hybrid actor's ``relevance`` and ``relevance_parametrisation`` names.

    Raises
    ------
    ValueError
        Naming the argument, with the expected and found values.
    """
    if relevance not in RELEVANCE_KINDS:
        raise ValueError(f"relevance: expected one of {RELEVANCE_KINDS}, found {relevance!r}")
    if relevance_parametrisation not in RELEVANCE_PARAMETRISATIONS:
        raise ValueError(
            f"relevance_parametrisation: expected one of {RELEVANCE_PARAMETRISATIONS}, "
            f"found {relevance_parametrisation!r}"
        )


class HybridActorMixin:
    r"""The LEOC blend in SB3's normalised action units, shared by the DDPG/TD3 and SAC actors.

    A hybrid actor class derives from this mixin and from an SB3 actor class, builds the SB3
    actor, takes its network :math:`\tilde H` (normalised units, bounded by tanh) out of it and
    calls :meth:`_init_hybrid`, which holds, for every hybrid actor alike, the linear part
    :math:`\tilde G(x) = (W x + b - c) / h`, the relevance (the paper's, its precision
    parametrisation, or the ROA relevance) and the blend :class:`~leoc.policies.HybridPolicy`
    (clip saturation to :math:`[-1, 1]`). See the module docstring for the units and the
    identities; :class:`HybridActor` (DDPG/TD3) and :class:`leoc.ddpg.sac.HybridSACActor` (SAC)
    differ only in what they do with the blend.

    Attributes
    ----------
    hybrid : HybridPolicy
        The blend in normalised units; its ``nonlinear`` is :math:`\tilde H`.
    physical_gain, physical_bias, operating_obs : Tensor
        float64 buffers with ``W``, ``b`` and ``a`` in physical units (for exact float64
        evaluation, see :func:`leoc.ddpg.physical_policy`).
    relevance_kind : {"paper", "roa"}
    roa_kwargs : dict
        The ``roa_*`` constructor data of an ROA relevance (empty otherwise).
    """

    hybrid: HybridPolicy
    physical_gain: Tensor
    physical_bias: Tensor
    operating_obs: Tensor
    action_space: spaces.Box
    features_extractor: nn.Module

    def _init_hybrid(
        self,
        nonlinear: nn.Module,
        features_dim: int,
        *,
        lqr_gain: object,
        lqr_bias: object,
        operating_obs: object,
        lambda_init: float | Sequence[float],
        learn_lambda: bool,
        relevance: str,
        relevance_parametrisation: str,
        roa_obs_layout: Sequence[Sequence[Any]] | None,
        roa_operating_state: Sequence[float] | None,
        roa_lyapunov_matrix: Sequence[Sequence[float]] | None,
        roa_rho_in: float | None,
        roa_width_init: float,
        learn_width: bool,
    ) -> None:
        """Build ``self.hybrid`` around ``nonlinear`` (:math:`\tilde H`, (B, D) -> (B, F)) and
        register the physical-units buffers (arguments: see :class:`HybridActor`)."""
        check_hybrid_options(relevance, relevance_parametrisation)
        act_dim = int(np.prod(self.action_space.shape))
        gain = _as_matrix(lqr_gain, "lqr_gain", (act_dim, features_dim))
        bias = _as_matrix(lqr_bias, "lqr_bias", (act_dim,))
        point = _as_matrix(operating_obs, "operating_obs", (features_dim,))
        centre, half = action_box(self.action_space)
        self.lqr_gain = gain.tolist()
        self.lqr_bias = bias.tolist()
        self.operating_obs_init = point.tolist()
        self.lambda_init = lambda_init
        self.learn_lambda = learn_lambda
        self.relevance_kind = relevance
        self.relevance_parametrisation = relevance_parametrisation
        self.roa_kwargs: dict[str, Any] = {}
        self.register_buffer("physical_gain", torch.as_tensor(gain))  # type: ignore[attr-defined]
        self.register_buffer("physical_bias", torch.as_tensor(bias))  # type: ignore[attr-defined]
        self.register_buffer("operating_obs", torch.as_tensor(point))  # type: ignore[attr-defined]
        # G in normalised units: (W x + b - c) / h.
        linear = LinearController(gain / half[:, None], (bias - centre) / half, dtype=ACTION_DTYPE)
        if relevance == "paper" and relevance_parametrisation == "precision":
            precision = PrecisionRelevance(
                point,
                1.0 / np.asarray(lambda_init, dtype=np.float64),
                learn_precision=learn_lambda,
                dtype=ACTION_DTYPE,
            )
            self.hybrid = HybridPolicy(
                linear,
                nonlinear,
                point,
                action_limit=NORMALISED_LIMIT,
                saturation="clip",
                relevance=precision,
            )
            return
        if relevance == "paper":
            self.hybrid = HybridPolicy(
                linear,
                nonlinear,
                point,
                lambda_init=lambda_init,
                learn_lambda=learn_lambda,
                action_limit=NORMALISED_LIMIT,
                saturation="clip",
            )
            return
        missing = [
            name
            for name, value in (
                ("roa_obs_layout", roa_obs_layout),
                ("roa_operating_state", roa_operating_state),
                ("roa_lyapunov_matrix", roa_lyapunov_matrix),
                ("roa_rho_in", roa_rho_in),
            )
            if value is None
        ]
        if missing:
            raise ValueError(f"relevance='roa' needs {', '.join(missing)}; found None")
        self.roa_kwargs = {
            "roa_obs_layout": [[str(kind), int(index)] for kind, index in roa_obs_layout],  # type: ignore[union-attr]
            "roa_operating_state": np.asarray(roa_operating_state, dtype=np.float64).tolist(),
            "roa_lyapunov_matrix": np.asarray(roa_lyapunov_matrix, dtype=np.float64).tolist(),
            "roa_rho_in": float(roa_rho_in),  # type: ignore[arg-type]
            "roa_width_init": float(roa_width_init),
            "learn_width": bool(learn_width),
        }
        self.hybrid = HybridPolicy(
            linear,
            nonlinear,
            point,
            action_limit=NORMALISED_LIMIT,
            saturation="clip",
            relevance=roa_relevance(self.roa_kwargs, ACTION_DTYPE),
        )

    def hybrid_constructor_parameters(self) -> dict[str, Any]:
        """The hybrid's constructor arguments (what SB3 saves to rebuild the actor)."""
        return {
            "lqr_gain": self.lqr_gain,
            "lqr_bias": self.lqr_bias,
            "operating_obs": self.operating_obs_init,
            "lambda_init": self.lambda_init,
            "learn_lambda": self.learn_lambda,
            "relevance": self.relevance_kind,
            "relevance_parametrisation": self.relevance_parametrisation,
            **self.roa_kwargs,
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


class HybridActor(HybridActorMixin, Actor):
    r"""SB3 TD3/DDPG actor whose output is the LEOC blend of an LQR controller and SB3's MLP.

    Output (normalised units, see the module docstring):
    :math:`\operatorname{clip}_{[-1,1]}(r \tilde G + (1 - r) \tanh(\mathrm{MLP}))`.
    Shapes: observation (B, D) float32 -> normalised action (B, F).

    Parameters
    ----------
    observation_space, action_space, net_arch, features_extractor, features_dim,
    activation_fn, normalize_images
        As for SB3's :class:`stable_baselines3.td3.policies.Actor`. The observation must be a
        flat box (the features are the observation itself) so that ``a`` and ``W`` act on it.
    lqr_gain : array-like, shape (F, D)
        ``W`` of the linear controller, in physical units (N or N m per observation unit).
    lqr_bias : array-like, shape (F,)
        ``b`` of the linear controller, in physical units.
    operating_obs : array-like, shape (D,)
        Operating point ``a`` in observation coordinates.
    lambda_init : float or array-like (D,)
        Initial diagonal of Lambda (> 0).
    learn_lambda : bool
        Whether ``log_lambda`` is an ``nn.Parameter`` (trained by the actor loss) or a buffer.
    relevance_parametrisation : {"log_lambda", "precision"}
        How the paper's relevance holds its weights: ``log_lambda`` (positive
        :math:`\lambda = e^{\ell}`, the default) or ``precision``: the precision
        :math:`S = \Lambda^{-1}` itself, unconstrained, starting at ``1 / lambda_init``
        (:class:`~leoc.policies.PrecisionRelevance`, nrjc/LEOC's ``S``); ``learn_lambda`` then
        says whether :math:`S` is trained.
    clip_output : bool
        Whether the actor clips its blend to [-1, 1] (default). False: the blend is returned
        unbounded, as TF-Agents' actor network returns ``scale_to_spec(r g + (1 - r) h)``
        (nrjc/LEOC ``DDPG/ddpg.py``), so the actor loss sees the critic beyond the box; the
        executed action is clipped all the same (SB3's collection, :func:`physical_policy`).
    relevance : {"paper", "roa"}
        ``paper``: :math:`r = (1 + d)^{-2}` with ``lambda_init``/``learn_lambda``. ``roa``:
        :class:`~leoc.policies.ROARelevance`, exactly 1 on the LQR's certified set
        :math:`\{V \le \rho_{in}\}` (needs the ``roa_*`` arguments;
        :func:`roa_relevance_kwargs` builds them). The relevance does not depend on the action
        scaling, so it is the same function in normalised and physical units.
    roa_obs_layout : list of (kind, state_index)
        ``System.obs_layout`` (how the observation is built from the state).
    roa_operating_state : array-like (S,)
        Operating point in state coordinates.
    roa_lyapunov_matrix : array-like (S, S)
        ``P`` of the LQR design.
    roa_rho_in : float
        Level of the flat top (at most the certified rho).
    roa_width_init : float
        Initial band width (see :class:`~leoc.policies.ROARelevance`).
    learn_width : bool
        Whether the band width is trained by the actor loss.

    Attributes
    ----------
    hybrid : HybridPolicy
        The blend in normalised units; its ``nonlinear`` is SB3's MLP (ending in tanh).
    physical_gain, physical_bias, operating_obs : Tensor
        float64 buffers with ``W``, ``b`` and ``a`` in physical units (for exact float64
        evaluation, see :func:`leoc.ddpg.physical_policy`).
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
        lqr_gain: object,
        lqr_bias: object,
        operating_obs: object,
        lambda_init: float | Sequence[float] = 1.0,
        learn_lambda: bool = True,
        relevance: str = "paper",
        relevance_parametrisation: str = "log_lambda",
        clip_output: bool = True,
        roa_obs_layout: Sequence[Sequence[Any]] | None = None,
        roa_operating_state: Sequence[float] | None = None,
        roa_lyapunov_matrix: Sequence[Sequence[float]] | None = None,
        roa_rho_in: float | None = None,
        roa_width_init: float = DEFAULT_ROA_WIDTH,
        learn_width: bool = True,
    ) -> None:
        check_hybrid_options(relevance, relevance_parametrisation)
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
        self._init_hybrid(
            mlp,
            features_dim,
            lqr_gain=lqr_gain,
            lqr_bias=lqr_bias,
            operating_obs=operating_obs,
            lambda_init=lambda_init,
            learn_lambda=learn_lambda,
            relevance=relevance,
            relevance_parametrisation=relevance_parametrisation,
            roa_obs_layout=roa_obs_layout,
            roa_operating_state=roa_operating_state,
            roa_lyapunov_matrix=roa_lyapunov_matrix,
            roa_rho_in=roa_rho_in,
            roa_width_init=roa_width_init,
            learn_width=learn_width,
        )
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


#: The ``roa_*`` keyword arguments of the hybrid actors (:func:`roa_relevance_kwargs`).
ROA_KWARG_NAMES = (
    "roa_obs_layout",
    "roa_operating_state",
    "roa_lyapunov_matrix",
    "roa_rho_in",
    "roa_width_init",
    "learn_width",
)


def hybrid_actor_kwargs(
    policy_kwargs: dict[str, Any],
    *,
    lqr_gain: object,
    lqr_bias: object,
    operating_obs: object,
    lambda_init: float | Sequence[float],
    learn_lambda: bool,
    relevance: str,
    relevance_parametrisation: str,
) -> dict[str, Any]:
    """The hybrid actor's keyword arguments of a hybrid policy, JSON-friendly.

    The ``roa_*`` entries (:data:`ROA_KWARG_NAMES`) are *popped* from ``policy_kwargs`` (what is
    left there is the SB3 policy's own); arrays become lists so that SB3 saves them with the
    model.
    """
    roa = {name: policy_kwargs.pop(name) for name in ROA_KWARG_NAMES if name in policy_kwargs}
    return {
        "lqr_gain": np.asarray(lqr_gain, dtype=np.float64).tolist(),
        "lqr_bias": np.asarray(lqr_bias, dtype=np.float64).tolist(),
        "operating_obs": np.asarray(operating_obs, dtype=np.float64).tolist(),
        "lambda_init": lambda_init,
        "learn_lambda": bool(learn_lambda),
        "relevance": relevance,
        "relevance_parametrisation": relevance_parametrisation,
        **roa,
    }


class HybridTD3Policy(LeocTD3Policy):
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
    lqr_gain, lqr_bias, operating_obs, lambda_init, learn_lambda, relevance,
    relevance_parametrisation, clip_output, roa_*, learn_width
        Passed to :class:`HybridActor` (see there); :func:`hybrid_policy_kwargs` builds them
        from a system's LQR design (and, for ``relevance="roa"``, its certificate).
    """

    actor: HybridActor
    actor_target: HybridActor

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Box,
        lr_schedule: Any,
        *args: Any,
        lqr_gain: object,
        lqr_bias: object,
        operating_obs: object,
        lambda_init: float | Sequence[float] = 1.0,
        learn_lambda: bool = True,
        relevance: str = "paper",
        relevance_parametrisation: str = "log_lambda",
        clip_output: bool = True,
        **kwargs: Any,
    ) -> None:
        self.hybrid_kwargs = {
            **hybrid_actor_kwargs(
                kwargs,
                lqr_gain=lqr_gain,
                lqr_bias=lqr_bias,
                operating_obs=operating_obs,
                lambda_init=lambda_init,
                learn_lambda=learn_lambda,
                relevance=relevance,
                relevance_parametrisation=relevance_parametrisation,
            ),
            "clip_output": bool(clip_output),
        }
        super().__init__(observation_space, action_space, lr_schedule, *args, **kwargs)

    def _new_actor(self, features_extractor: nn.Module | None = None) -> HybridActor:
        actor_kwargs = self._update_features_extractor(self.actor_kwargs, features_extractor)
        return HybridActor(**actor_kwargs, **self.hybrid_kwargs).to(self.device)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(self.hybrid_kwargs)
        return data


HybridDDPGPolicy = HybridTD3Policy
"""SB3's DDPG uses TD3's policy classes (with one critic); the hybrid policy is shared too."""


def roa_relevance(kwargs: dict[str, Any], dtype: torch.dtype) -> ROARelevance:
    """The :class:`~leoc.policies.ROARelevance` of :class:`HybridActor`'s ``roa_*`` kwargs."""
    return ROARelevance(
        [tuple(entry) for entry in kwargs["roa_obs_layout"]],
        kwargs["roa_operating_state"],
        kwargs["roa_lyapunov_matrix"],
        kwargs["roa_rho_in"],
        width_init=kwargs["roa_width_init"],
        learn_width=kwargs["learn_width"],
        dtype=dtype,
    )


def roa_relevance_kwargs(
    system: Any,
    design: Any,
    rho_in_fraction: float = 1.0,
    width_init: float = DEFAULT_ROA_WIDTH,
    learn_width: bool = True,
    certificate: Any = None,
) -> dict[str, Any]:
    """``roa_*`` kwargs of :class:`HybridActor` from a system, its LQR design and certificate.

    Parameters
    ----------
    system : leoc.systems.System
    design : LQRDesign
        The design whose ``W, b`` the actor uses (its ``P`` defines V).
    rho_in_fraction : float in (0, 1]
        Flat top level ``rho_in = rho_in_fraction * rho``.
    width_init, learn_width
        See :class:`~leoc.policies.ROARelevance`.
    certificate : LyapunovCertificate, optional
        Default :func:`leoc.control.certify_lqr` of ``design`` (default options, seed 0).

    Raises
    ------
    ValueError
        If ``rho_in_fraction`` is outside (0, 1] or the design has no certificate (rho = 0).
    """
    from leoc.control import certify_lqr

    if not 0.0 < rho_in_fraction <= 1.0:
        raise ValueError(f"rho_in_fraction: expected a number in (0, 1], found {rho_in_fraction!r}")
    certificate = certify_lqr(system, design) if certificate is None else certificate
    if not certificate.certified:
        raise ValueError(
            f"relevance='roa': the LQR of {system.name} has no certified region of attraction "
            f"(rho = 0, linear decrease {certificate.linear_decrease}); use relevance='paper'"
        )
    return {
        "roa_obs_layout": system.observation.to_list(),
        "roa_operating_state": np.asarray(system.operating_state, dtype=np.float64).tolist(),
        "roa_lyapunov_matrix": np.asarray(design.P, dtype=np.float64).tolist(),
        "roa_rho_in": float(rho_in_fraction * certificate.rho),
        "roa_width_init": float(width_init),
        "learn_width": bool(learn_width),
    }


def hybrid_policy_kwargs(
    system: Any,
    lambda_init: float | Sequence[float] = 1.0,
    learn_lambda: bool = True,
    lqr_method: str = "discrete",
    relevance: str = "paper",
    relevance_parametrisation: str = "log_lambda",
    clip_output: bool = True,
    rho_in_fraction: float = 1.0,
    width_init: float = DEFAULT_ROA_WIDTH,
    learn_width: bool = True,
    **extra: Any,
) -> dict[str, Any]:
    """``policy_kwargs`` for :class:`HybridTD3Policy` from a system's LQR design.

    Parameters
    ----------
    system : leoc.systems.System or str
        The system (or its name); ``W, b`` come from :func:`leoc.control.design_lqr` and ``a``
        is ``system.operating_obs``.
    lambda_init, learn_lambda, relevance_parametrisation, clip_output
        See :class:`HybridActor`.
    lqr_method : {"discrete", "continuous", "authors"}
        LQR design method.
    relevance : {"paper", "roa"}
        The paper's relevance, or the ROA relevance flat on the LQR's certified set
        (:func:`roa_relevance_kwargs`, with ``rho_in_fraction``, ``width_init``,
        ``learn_width``).
    **extra
        Further policy kwargs (``net_arch``, ...).
    """
    from leoc.control import design_lqr
    from leoc.systems import make_system

    if isinstance(system, str):
        system = make_system(system)
    if relevance not in RELEVANCE_KINDS:
        raise ValueError(f"relevance: expected one of {RELEVANCE_KINDS}, found {relevance!r}")
    design = design_lqr(system, method=lqr_method)  # type: ignore[arg-type]
    roa: dict[str, Any] = {}
    if relevance == "roa":
        roa = roa_relevance_kwargs(system, design, rho_in_fraction, width_init, learn_width)
    return {
        "lqr_gain": design.W.tolist(),
        "lqr_bias": design.b.tolist(),
        "operating_obs": np.asarray(system.operating_obs, dtype=np.float64).tolist(),
        "lambda_init": lambda_init,
        "learn_lambda": learn_lambda,
        "relevance": relevance,
        "relevance_parametrisation": relevance_parametrisation,
        "clip_output": clip_output,
        **roa,
        **extra,
    }
