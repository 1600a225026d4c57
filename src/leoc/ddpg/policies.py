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

References
----------
Y. Zhang and F. Capel, "LEOC: A Principled Method in Integrating Reinforcement Learning and
Classical Control Theory", L4DC 2021, eq. 4-5.
T. P. Lillicrap et al., "Continuous control with deep reinforcement learning", ICLR 2016.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.td3.policies import Actor, TD3Policy
from torch import Tensor, nn

from leoc.policies import HybridPolicy, LinearController

__all__ = [
    "HybridActor",
    "HybridDDPGPolicy",
    "HybridTD3Policy",
    "action_box",
    "hybrid_policy_kwargs",
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


class HybridActor(Actor):
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
        act_dim = int(np.prod(action_space.shape))
        gain = _as_matrix(lqr_gain, "lqr_gain", (act_dim, features_dim))
        bias = _as_matrix(lqr_bias, "lqr_bias", (act_dim,))
        point = _as_matrix(operating_obs, "operating_obs", (features_dim,))
        centre, half = action_box(action_space)
        self.lqr_gain = gain.tolist()
        self.lqr_bias = bias.tolist()
        self.operating_obs_init = point.tolist()
        self.lambda_init = lambda_init
        self.learn_lambda = learn_lambda
        self.register_buffer("physical_gain", torch.as_tensor(gain))
        self.register_buffer("physical_bias", torch.as_tensor(bias))
        self.register_buffer("operating_obs", torch.as_tensor(point))
        # G in normalised units: (W x + b - c) / h.
        linear = LinearController(gain / half[:, None], (bias - centre) / half, dtype=ACTION_DTYPE)
        mlp = self.mu
        del self.mu  # the MLP lives on as hybrid.nonlinear (one copy in the state_dict)
        self.hybrid = HybridPolicy(
            linear,
            mlp,
            point,
            lambda_init=lambda_init,
            learn_lambda=learn_lambda,
            action_limit=NORMALISED_LIMIT,
            saturation="clip",
        )

    @property
    def nonlinear(self) -> nn.Module:
        """SB3's MLP, :math:`\\tilde H = \\tanh(\\mathrm{MLP})`, in normalised units."""
        return self.hybrid.nonlinear

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(
            lqr_gain=self.lqr_gain,
            lqr_bias=self.lqr_bias,
            operating_obs=self.operating_obs_init,
            lambda_init=self.lambda_init,
            learn_lambda=self.learn_lambda,
        )
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
        hybrid = self.hybrid
        offset = features - hybrid.operating_point
        distance = offset.square() @ torch.exp(-hybrid.log_lambda)  # (B,)
        relevance = torch.reciprocal(torch.square(distance + 1.0)).unsqueeze(-1)  # (B, 1)
        linear = torch.addmm(hybrid.linear.b, features, hybrid.linear.W.T)  # (B, F)
        blend = torch.lerp(hybrid.nonlinear(features), linear, relevance)
        return torch.clamp(blend, -NORMALISED_LIMIT, NORMALISED_LIMIT)

    def relevance(self, obs: Tensor) -> Tensor:
        """Relevance :math:`r(x)` of the linear part, shape (B, 1)."""
        features = self.extract_features(obs, self.features_extractor)
        return self.hybrid.relevance(features)


class HybridTD3Policy(TD3Policy):
    """SB3 TD3/DDPG policy whose actor and target actor are :class:`HybridActor`.

    Use it as ``DDPG(HybridTD3Policy, env, policy_kwargs=hybrid_policy_kwargs(system))`` or
    with ``TD3``. The critics are SB3's; only the actor changes.

    Parameters
    ----------
    observation_space, action_space, lr_schedule, net_arch, activation_fn, ...
        As for :class:`stable_baselines3.td3.policies.TD3Policy`.
    lqr_gain, lqr_bias, operating_obs, lambda_init, learn_lambda
        Passed to :class:`HybridActor` (see there); :func:`hybrid_policy_kwargs` builds them
        from a system's LQR design.
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
        **kwargs: Any,
    ) -> None:
        self.hybrid_kwargs = {
            "lqr_gain": np.asarray(lqr_gain, dtype=np.float64).tolist(),
            "lqr_bias": np.asarray(lqr_bias, dtype=np.float64).tolist(),
            "operating_obs": np.asarray(operating_obs, dtype=np.float64).tolist(),
            "lambda_init": lambda_init,
            "learn_lambda": bool(learn_lambda),
        }
        super().__init__(observation_space, action_space, lr_schedule, *args, **kwargs)

    def make_actor(self, features_extractor: nn.Module | None = None) -> HybridActor:
        actor_kwargs = self._update_features_extractor(self.actor_kwargs, features_extractor)
        return HybridActor(**actor_kwargs, **self.hybrid_kwargs).to(self.device)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(self.hybrid_kwargs)
        return data


HybridDDPGPolicy = HybridTD3Policy
"""SB3's DDPG uses TD3's policy classes (with one critic); the hybrid policy is shared too."""


def hybrid_policy_kwargs(
    system: Any,
    lambda_init: float | Sequence[float] = 1.0,
    learn_lambda: bool = True,
    lqr_method: str = "discrete",
    **extra: Any,
) -> dict[str, Any]:
    """``policy_kwargs`` for :class:`HybridTD3Policy` from a system's LQR design.

    Parameters
    ----------
    system : leoc.systems.System or str
        The system (or its name); ``W, b`` come from :func:`leoc.control.design_lqr` and ``a``
        is ``system.operating_obs``.
    lambda_init, learn_lambda
        See :class:`HybridActor`.
    lqr_method : {"discrete", "continuous"}
        LQR design method.
    **extra
        Further policy kwargs (``net_arch``, ...).
    """
    from leoc.control import design_lqr
    from leoc.systems import make_system

    if isinstance(system, str):
        system = make_system(system)
    design = design_lqr(system, method=lqr_method)  # type: ignore[arg-type]
    return {
        "lqr_gain": design.W.tolist(),
        "lqr_bias": design.b.tolist(),
        "operating_obs": np.asarray(system.operating_obs, dtype=np.float64).tolist(),
        "lambda_init": lambda_init,
        "learn_lambda": learn_lambda,
        **extra,
    }
