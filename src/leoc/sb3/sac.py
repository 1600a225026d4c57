r"""The LEOC hybrid for Stable-Baselines3's SAC: the squashed mean is the hybrid of DDPG/TD3.

Letters: B batch, D observation dimension, F action dimension. Units as in
:mod:`leoc.sb3.common`: SB3 acts in normalised units :math:`\tilde u \in [-1, 1]^F`,
:math:`u = c + h \odot \tilde u`.

SAC's policy (Haarnoja et al., 2018) is a squashed Gaussian: in normalised units
:math:`\tilde u = \tanh(z)`, :math:`z \sim \mathcal N(\mu(x), \operatorname{diag}\sigma(x)^2)`,
with mean :math:`\mu` and log-std :math:`\log\sigma` two heads on one MLP; its deterministic
action is the squashed mean :math:`\tanh\mu(x)`. SB3's mean head is unbounded; call it
:math:`M(x)`, so that SB3's squashed mean is :math:`\tilde H(x) = \tanh M(x)`.

**Construction.** The hybrid keeps SAC's log-std head and replaces the mean by

.. math::

    \mu(x) = \operatorname{atanh}\big(\operatorname{clip}_{[-1 + \epsilon, 1 - \epsilon]}
        \beta(x)\big), \qquad
    \beta(x) = r(x)\, \tilde G(x) + (1 - r(x))\, \tanh M(x),

with :math:`\tilde G = (W x + b - c) / h` the LQR in normalised units and :math:`r` the paper's
or the ROA relevance, exactly as in :class:`~leoc.sb3.HybridActor` (the blend, its relevance and
its saved arguments are :class:`~leoc.sb3.common.HybridActorMixin`'s, shared with DDPG/TD3).
The squash undoes the atanh, so the deterministic action is the DDPG/TD3 hybrid's,

.. math::

    \tanh\mu(x) = \operatorname{clip}(\beta(x)) \quad\Longrightarrow\quad
    \pi(x) = c + h \odot \tanh\mu(x)
           = \operatorname{clip}_{[u_{low}, u_{high}]}\big(r G + (1 - r) H\big), \qquad
    H = c + h \odot \tanh M,

a LEOC hybrid whose nonlinear part is SB3's own squashed mean (up to :math:`\epsilon h`, the
dtype's machine epsilon times the half-width, where the clip acts). SAC explores with its own
entropy-regularised, state-dependent Gaussian :math:`z \sim \mathcal N(\mu, \sigma^2)` around
this mean, and its log-probability (with SB3's tanh correction) is the one of that Gaussian.

**Identities after squashing.** :math:`r(a) = 1` and :math:`\nabla r(a) = 0` give
:math:`\beta(a) = \tilde G(a)` and :math:`\partial\beta/\partial x(a) = W / h` (the blend's
identities, :mod:`leoc.policies.hybrid`). If :math:`|\tilde G(a)| < 1 - \epsilon` (``G(a)``
strictly inside the box), the clip is the identity near :math:`a`, and

.. math::

    \tanh\mu(a) = \tilde G(a), \qquad
    \frac{\partial \tanh\mu}{\partial x}
        = (1 - \tanh^2\mu)\, \frac{\partial\mu}{\partial x}
        = (1 - \beta^2)\, \frac{1}{1 - \beta^2}\, \frac{\partial\beta}{\partial x}
        = \frac{\partial\beta}{\partial x} \;\xrightarrow{x = a}\; W / h,

so in physical units :math:`\pi(a) = G(a)` and :math:`\partial\pi/\partial x(a) = W`. Wherever
:math:`r = 1` (the ROA relevance's flat top) and :math:`|\tilde G| < 1 - \epsilon`,
:math:`\tanh\mu = \tilde G`: the squashed mean is the LQR itself (to the round-off of
:math:`\tanh\circ\operatorname{atanh}`, about one unit in the last place).

**Evaluation without cancellation.** :math:`\operatorname{atanh}\beta =
\tfrac12 \log\frac{1 + \beta}{1 - \beta}`, and both :math:`1 \pm \beta` are convex combinations
of non-negative terms,

.. math::

    1 \pm \beta = r\, (1 \pm \tilde G) + (1 - r)\, 2\,\varsigma(\pm 2 M),

with :math:`\varsigma` the logistic sigmoid (:math:`1 \pm \tanh M = 2\varsigma(\pm 2M)`, exact).
:func:`squashed_blend_mean` evaluates this form: no :math:`1 - \tanh M` is formed by
subtraction, so where :math:`r = 0` the mean is SB3's own :math:`M` (to relative round-off)
instead of :math:`\operatorname{atanh}(\tanh M)` losing its digits once :math:`\tanh M` rounds
towards 1. The clip is a clamp of :math:`1 \pm \beta` to :math:`[\epsilon, 2 - \epsilon]`,
which bounds :math:`|\mu| \le \operatorname{atanh}(1 - \epsilon)` (about 8.3 in float32; SB3's
``TanhBijector.inverse`` clamps the same way). The gradient is well conditioned: for
:math:`|\tilde G| \le 1`, :math:`0 \le \partial\mu/\partial M = (1 - r)(1 - \tanh^2 M) /
(1 - \beta^2) \le 2`, since :math:`1 \mp \beta \ge (1 - r)(1 \mp \tanh M)`.

Why not blend in the pre-tanh space, :math:`\mu = r \operatorname{atanh}\tilde G + (1 - r) M`?
It has the same identities at :math:`a`, but its deterministic action
:math:`\tanh(r \operatorname{atanh}\tilde G + (1 - r) M)` is not :math:`r G + (1 - r) H` away
from :math:`a`; the form above is the LEOC hybrid everywhere, the same function class as the
DDPG/TD3 hybrid, so one float64 evaluation (:func:`leoc.sb3.physical_policy`), one relevance
trace and one set of hybrid claims serve all three learners.

References
----------
T. Haarnoja, A. Zhou, P. Abbeel and S. Levine, "Soft Actor-Critic: Off-Policy Maximum Entropy
Deep Reinforcement Learning with a Stochastic Actor", ICML 2018 (and "Soft Actor-Critic
Algorithms and Applications", arXiv:1812.05905: automatic entropy tuning).
Y. Zhang and F. Capel, "LEOC: A Principled Method in Integrating Reinforcement Learning and
Classical Control Theory", L4DC 2021, eq. 4-5.
"""

from __future__ import annotations

from typing import Any

import torch
from gymnasium import spaces
from stable_baselines3 import SAC
from stable_baselines3.common.utils import polyak_update
from stable_baselines3.sac.policies import LOG_STD_MAX, LOG_STD_MIN, SACPolicy
from stable_baselines3.sac.policies import Actor as SACActor
from torch import Tensor, nn

from leoc.policies.spec import HybridDesign, HybridSpec
from leoc.sb3.common import (
    ActorRateAndWarmupMixin,
    HybridActorMixin,
    HybridPolicyMixin,
    NetworkOptionsMixin,
    critic_loss_fn,
    hybrid_arguments,
    policy_of,
)
from leoc.sb3.noise import exploration_noise

__all__ = [
    "HybridSACActor",
    "HybridSACPolicy",
    "LeocSAC",
    "LeocSACPolicy",
    "SquashedMean",
    "build_sac_model",
    "squashed_blend_mean",
]

NO_TARGET_UPDATE = 0.0  # Polyak coefficient that leaves the targets unchanged


def squashed_blend_mean(linear: Tensor, pre_squash: Tensor, relevance: Tensor) -> Tensor:
    r"""Pre-tanh mean :math:`\mu = \operatorname{atanh}\operatorname{clip}(r \tilde G + (1 - r)
    \tanh M)`, evaluated as :math:`\tfrac12 \log\frac{1 + \beta}{1 - \beta}` without
    cancellation (see the module docstring).

    Parameters
    ----------
    linear : Tensor (B, F)
        :math:`\tilde G(x)`, the linear part in normalised units (any real value; outside
        :math:`[-1, 1]` it is clipped after blending).
    pre_squash : Tensor (B, F)
        :math:`M(x)`, SAC's unbounded mean head.
    relevance : Tensor (B, 1)
        :math:`r(x) \in [0, 1]`.

    Returns
    -------
    Tensor (B, F)
        :math:`\mu`, with :math:`|\mu| \le \operatorname{atanh}(1 - \epsilon)`, :math:`\epsilon`
        the machine epsilon of ``linear``'s dtype. Where ``relevance == 1`` it depends on
        ``linear`` only (``0 * M`` adds an exact zero), so :math:`\tanh\mu = \tilde G` there.
    """
    floor = torch.finfo(linear.dtype).eps
    ceiling = 2.0 - floor
    rest = 1.0 - relevance
    # 1 +/- tanh(M) = 2 sigmoid(+/- 2M), exactly, and without forming 1 - tanh(M) by subtraction
    plus = relevance * (1.0 + linear) + rest * (2.0 * torch.sigmoid(2.0 * pre_squash))
    minus = relevance * (1.0 - linear) + rest * (2.0 * torch.sigmoid(-2.0 * pre_squash))
    # clamping 1 + beta and 1 - beta to [eps, 2 - eps] is the clip of beta to +/-(1 - eps)
    return 0.5 * (torch.log(plus.clamp(floor, ceiling)) - torch.log(minus.clamp(floor, ceiling)))


class SquashedMean(nn.Module):
    r"""SAC's squashed mean :math:`\tanh M(x)`, :math:`M = \mathrm{mean}(\mathrm{latent}(x))`.

    The nonlinear part :math:`\tilde H` of :class:`HybridSACActor` (normalised units) and of a
    SAC baseline's float64 copy. Shapes: (B, D) -> (B, F).

    Parameters
    ----------
    latent : nn.Module
        SB3's ``latent_pi`` (the hidden layers, shared with the log-std head).
    mean : nn.Module
        SB3's ``mu`` (the linear mean head).
    """

    def __init__(self, latent: nn.Module, mean: nn.Module) -> None:
        super().__init__()
        self.latent = latent
        self.mean = mean

    def forward(self, x: Tensor) -> Tensor:
        """:math:`\\tanh M(x)`, shape (B, F)."""
        return torch.tanh(self.mean(self.latent(x)))


class HybridSACActor(HybridActorMixin, SACActor):
    r"""SB3 SAC actor whose squashed mean is the LEOC hybrid (see the module docstring).

    Mean :math:`\mu = \operatorname{atanh}\operatorname{clip}(r \tilde G + (1 - r) \tanh M)`
    (:func:`squashed_blend_mean`), log-std SB3's head on the same hidden layers (clamped to
    SB3's ``[LOG_STD_MIN, LOG_STD_MAX]``). Deterministic action
    :math:`\tanh\mu = \operatorname{clip}(r \tilde G + (1 - r) \tilde H)`, the
    :class:`~leoc.sb3.HybridActor`'s; sampled action :math:`\tanh(\mu + \sigma \xi)`,
    :math:`\xi \sim \mathcal N(0, I)`. Shapes: observation (B, D) float32 -> normalised action
    (B, F).

    Parameters
    ----------
    observation_space, action_space, net_arch, features_extractor, features_dim,
    activation_fn, log_std_init, full_std, use_expln, clip_mean, normalize_images
        As for SB3's :class:`stable_baselines3.sac.policies.Actor` (the observation a flat box).
    use_sde : bool
        Must be False: gSDE clips SAC's mean to ``+/- clip_mean``, which would move
        :math:`\mu(a)` off :math:`\operatorname{atanh}\tilde G(a)`.
    hybrid_spec, hybrid_design
        The hybrid, as for :class:`~leoc.sb3.HybridActor`.

    Attributes
    ----------
    hybrid : HybridPolicy
        The blend in normalised units; ``hybrid.nonlinear`` is a :class:`SquashedMean` holding
        SB3's hidden layers and mean head.
    physical_gain, physical_bias, operating_obs : Tensor
        float64 ``W``, ``b`` and ``a`` in physical units.
    log_std : nn.Linear
        SAC's log-std head.

    Raises
    ------
    ValueError
        If ``use_sde`` is True, or on a bad hybrid argument (naming it).
    """

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Box,
        net_arch: list[int],
        features_extractor: nn.Module,
        features_dim: int,
        activation_fn: type[nn.Module] = nn.ReLU,
        use_sde: bool = False,
        log_std_init: float = -3,
        full_std: bool = True,
        use_expln: bool = False,
        clip_mean: float = 2.0,
        normalize_images: bool = True,
        *,
        hybrid_spec: HybridSpec | dict[str, Any],
        hybrid_design: HybridDesign | dict[str, Any],
    ) -> None:
        _check_no_sde(use_sde)
        super().__init__(
            observation_space,
            action_space,
            net_arch,
            features_extractor,
            features_dim,
            activation_fn,
            use_sde,
            log_std_init,
            full_std,
            use_expln,
            clip_mean,
            normalize_images,
        )
        nonlinear = SquashedMean(self.latent_pi, self.mu)
        # the hidden layers and the mean head live on in hybrid.nonlinear (one copy each in the
        # state_dict); the log-std head stays where SB3 put it
        del self.latent_pi, self.mu
        self._init_hybrid(nonlinear, features_dim, hybrid_spec, hybrid_design)

    @property
    def nonlinear(self) -> SquashedMean:
        """SAC's squashed mean :math:`\\tilde H = \\tanh M`, in normalised units."""
        return self.hybrid.nonlinear  # type: ignore[return-value]

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(self.hybrid_constructor_parameters())
        return data

    def get_action_dist_params(self, obs: Tensor) -> tuple[Tensor, Tensor, dict[str, Tensor]]:
        r"""Mean :math:`\mu` (B, F), log-std (B, F) and SB3's extra kwargs (none).

        One pass through the hidden layers serves both heads; the relevance and
        :math:`\tilde G` come from :meth:`fused_relevance_and_linear`.
        """
        features = self.extract_features(obs, self.features_extractor)
        latent = self.nonlinear.latent(features)
        relevance, linear = self.fused_relevance_and_linear(features)
        mean = squashed_blend_mean(linear, self.nonlinear.mean(latent), relevance)
        log_std = torch.clamp(self.log_std(latent), LOG_STD_MIN, LOG_STD_MAX)  # type: ignore[operator]
        return mean, log_std, {}


def _check_no_sde(use_sde: object) -> None:
    if use_sde:
        raise ValueError(
            "use_sde: the SAC hybrid needs SAC's unstructured Gaussian (use_sde=False); gSDE "
            f"clips the mean to +/- clip_mean, which breaks pi(a) = G(a); found {use_sde!r}"
        )


class LeocSACPolicy(NetworkOptionsMixin, SACPolicy):
    """SB3's SAC policy with the critic layout and the networks' initialisation as options
    (:class:`~leoc.sb3.common.NetworkOptionsMixin`, as for DDPG/TD3): at their defaults
    it is SB3's ``SACPolicy`` itself (same modules, same random draws, same numbers).

    Parameters
    ----------
    observation_space, action_space, lr_schedule, net_arch, activation_fn, ...
        As for :class:`stable_baselines3.sac.policies.SACPolicy`.
    critic_action_layer, critic_action_units, hidden_init, last_layer_init
        As :class:`~leoc.sb3.common.NetworkOptionsMixin` describes them. The actor's
        initialised layers are its hidden layers and mean head (the squashed mean
        :class:`SquashedMean`, the hybrid's nonlinear part); the log-std head keeps SB3's.
    """

    def _new_actor(self, features_extractor: nn.Module | None = None) -> SACActor:
        return super().make_actor(features_extractor)

    def make_actor(self, features_extractor: nn.Module | None = None) -> SACActor:
        """The actor (SB3's, or the hybrid in :class:`HybridSACPolicy`), its hidden layers and
        mean head initialised as ``network_options`` says."""
        actor = self._new_actor(features_extractor)
        if isinstance(actor, HybridSACActor):
            self._initialise(actor.nonlinear)
        else:
            self._initialise(SquashedMean(actor.latent_pi, actor.mu))
        return actor


class HybridSACPolicy(HybridPolicyMixin, LeocSACPolicy):
    """SB3 SAC policy whose actor is :class:`HybridSACActor` (the critics, and the network
    options, :class:`LeocSACPolicy`'s).

    Use it as ``SAC(HybridSACPolicy, env, policy_kwargs=hybrid_policy_kwargs(system))``
    (:func:`leoc.sb3.hybrid_policy_kwargs`, the same helper as for DDPG/TD3) or through
    :func:`leoc.sb3.train_ddpg` with ``algo="sac", hybrid=True``.

    Parameters
    ----------
    observation_space, action_space, lr_schedule, net_arch, activation_fn, ...
        As for :class:`stable_baselines3.sac.policies.SACPolicy`.
    hybrid_spec, hybrid_design
        Passed to :class:`HybridSACActor`.
    clip_output : bool
        Accepted so that one ``policy_kwargs`` serves every hybrid; must be True (the squash
        bounds SAC's action by construction).

    Raises
    ------
    ValueError
        If ``clip_output`` is False or ``use_sde`` is True (naming the argument).
    """

    actor: HybridSACActor
    hybrid_actor_class = HybridSACActor  # built once: SAC has no target actor

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Box,
        lr_schedule: Any,
        *args: Any,
        clip_output: bool = True,
        **kwargs: Any,
    ) -> None:
        if clip_output is not True:
            raise ValueError(
                "clip_output: the SAC hybrid's action is bounded by its squash; expected True, "
                f"found {clip_output!r}"
            )
        _check_no_sde(kwargs.get("use_sde", False))
        self.hybrid_kwargs = hybrid_arguments(kwargs)
        super().__init__(observation_space, action_space, lr_schedule, *args, **kwargs)


class LeocSAC(ActorRateAndWarmupMixin, SAC):
    r"""SB3's ``SAC`` plus ``actor_learning_rate``, ``warmup``, a target update interval
    counted over all gradient updates, and the critics' loss.

    Parameters
    ----------
    *args, **kwargs
        As for :class:`stable_baselines3.SAC` (``learning_rate`` is the critics' and the
        entropy coefficient's step size).
    actor_learning_rate : float, optional
        The actor optimiser's step size (None: ``learning_rate``, SB3's behaviour).
    warmup : {"uniform", "policy"}
        How the first ``learning_starts`` steps act (:mod:`leoc.sb3.common`).
    target_update_interval : int
        Gradient updates between two soft target updates of the critics (default 1: every
        update, SAC's usual setting), as for :class:`~leoc.sb3.LeocDDPG`. SB3's SAC counts it
        over the gradient steps of *one* ``train`` call, so with ``train_freq=1,
        gradient_steps=1`` it would update the targets every step whatever its value; here
        it counts SB3's ``_n_updates`` across calls.
    critic_loss : {"mse", "huber"}
        The critics' TD loss: ``"mse"`` is SB3's update itself; ``"huber"`` runs
        :meth:`_train_step`, the same update with
        :math:`\tfrac12 \sum_k \mathrm{huber}(Q_k(s, a), y)` (delta 1, as DDPG's
        ``critic_loss``, :func:`leoc.sb3.common.critic_loss_fn`): a TD error beyond 1
        pulls with a constant gradient instead of one proportional to the error. leoc's
        defaults take it (:data:`~leoc.sb3.SAC_DEFAULTS`): with the squared error SAC did not
        learn the cart-pole swing-up (the DDPG guide, "SAC's critic loss").
    """

    def __init__(
        self,
        *args: Any,
        actor_learning_rate: float | None = None,
        warmup: str = "uniform",
        target_update_interval: int = 1,
        critic_loss: str = "mse",
        **kwargs: Any,
    ) -> None:
        if isinstance(target_update_interval, bool) or not (
            isinstance(target_update_interval, int) and target_update_interval >= 1
        ):
            raise ValueError(
                f"target_update_interval: expected an int >= 1, found {target_update_interval!r}"
            )
        critic_loss_fn(critic_loss)  # validates the name
        self.critic_loss = critic_loss
        self._init_actor_rate_and_warmup(actor_learning_rate, warmup)
        super().__init__(*args, target_update_interval=target_update_interval, **kwargs)
        self.polyak = float(self.tau)

    def train(self, gradient_steps: int, batch_size: int = 64) -> None:
        """SB3's SAC update (:meth:`_train_step` with the Huber loss); with
        ``target_update_interval > 1`` one gradient step at a time, the Polyak coefficient zero
        on the updates between two soft target updates (SB3's own check then always passes:
        each call's single step is its step 0)."""
        if self.target_update_interval == 1:
            self._train_calls(gradient_steps, batch_size)
            return
        for _ in range(gradient_steps):
            due = (self._n_updates + 1) % self.target_update_interval == 0
            self.tau = self.polyak if due else NO_TARGET_UPDATE
            self._train_calls(1, batch_size)
        self.tau = self.polyak

    def _train_calls(self, gradient_steps: int, batch_size: int) -> None:
        """SB3's ``SAC.train`` with the MSE loss, else :meth:`_train_step` per step."""
        if getattr(self, "critic_loss", "mse") == "mse":  # models saved before the option
            super().train(gradient_steps, batch_size)
            return
        self.policy.set_training_mode(True)
        optimisers = [self.actor.optimizer, self.critic.optimizer]
        if self.ent_coef_optimizer is not None:
            optimisers.append(self.ent_coef_optimizer)
        self._update_learning_rate(optimisers)
        loss_fn = critic_loss_fn(self.critic_loss)
        for _ in range(gradient_steps):
            self._train_step(batch_size, loss_fn)
        self._n_updates += gradient_steps

    def _train_step(self, batch_size: int, loss_fn: Any) -> None:
        r"""One SAC gradient step (Haarnoja et al. 2018, with the automatic entropy coefficient
        of arXiv:1812.05905), in SB3's order and with its random draws, the critics' loss
        ``loss_fn``.

        With :math:`a_\pi, \log\pi` sampled from the actor at :math:`s`: the entropy
        coefficient's loss :math:`-\log\alpha\,(\log\pi + \bar{\mathcal H})` (when it is
        learned; :math:`\alpha` itself enters the other losses detached, at its value before
        this step's update); target :math:`y = r + (1 - d)\,\gamma\,(\min_k Q'_k(s', a') -
        \alpha \log\pi(a' | s'))`, :math:`a' \sim \pi(\cdot | s')`; critics' loss
        :math:`\tfrac12 \sum_k \mathrm{loss}(Q_k(s, a), y)`; actor's loss
        :math:`\mathrm{mean}(\alpha \log\pi - \min_k Q_k(s, a_\pi))` with the critics just
        updated; then the soft target update with coefficient ``tau``.
        """
        data = self.replay_buffer.sample(batch_size, env=self._vec_normalize_env)  # type: ignore[union-attr]
        discounts = data.discounts if data.discounts is not None else self.gamma
        actions_pi, log_prob = self.actor.action_log_prob(data.observations)
        log_prob = log_prob.reshape(-1, 1)
        if self.ent_coef_optimizer is not None and self.log_ent_coef is not None:
            alpha = torch.exp(self.log_ent_coef.detach())
            alpha_loss = -(self.log_ent_coef * (log_prob + self.target_entropy).detach()).mean()
            self.ent_coef_optimizer.zero_grad()
            alpha_loss.backward()
            self.ent_coef_optimizer.step()
        else:
            alpha = self.ent_coef_tensor
        with torch.no_grad():
            next_actions, next_log_prob = self.actor.action_log_prob(data.next_observations)
            next_q = torch.cat(self.critic_target(data.next_observations, next_actions), dim=1)
            next_q = torch.min(next_q, dim=1, keepdim=True)[0] - alpha * next_log_prob.reshape(
                -1, 1
            )
            target_q = data.rewards + (1 - data.dones) * discounts * next_q
        current_q = self.critic(data.observations, data.actions)
        critic_loss = 0.5 * sum(loss_fn(q, target_q) for q in current_q)
        self.critic.optimizer.zero_grad()
        critic_loss.backward()  # type: ignore[union-attr]
        self.critic.optimizer.step()
        q_pi = torch.cat(self.critic(data.observations, actions_pi), dim=1)
        actor_loss = (alpha * log_prob - torch.min(q_pi, dim=1, keepdim=True)[0]).mean()
        self.actor.optimizer.zero_grad()
        actor_loss.backward()
        self.actor.optimizer.step()
        polyak_update(self.critic.parameters(), self.critic_target.parameters(), self.tau)
        polyak_update(self.batch_norm_stats, self.batch_norm_stats_target, 1.0)


def build_sac_model(
    config: Any, seed: int, env: Any, hybrid_kwargs: dict[str, Any] | None = None
) -> LeocSAC:
    """The :class:`LeocSAC` model of a :class:`~leoc.sb3.DDPGConfig` with ``algo="sac"``.

    Baseline: SB3's ``SACPolicy`` with ``actor_hidden``/``critic_hidden`` MLPs. Hybrid:
    :class:`HybridSACPolicy` with the system's LQR design (``lqr_method``) and the config's
    relevance (paper or ROA), or ``hybrid_kwargs`` (:func:`~leoc.sb3.common.policy_of`).
    ``seed`` seeds SB3 (torch, numpy, random, action space): SAC's Gaussian samples come from
    torch's generator, so the run repeats exactly.
    """
    # LeocSACPolicy is SB3's SACPolicy when the network options are at their defaults
    policy, policy_kwargs = policy_of(config, env, LeocSACPolicy, HybridSACPolicy, hybrid_kwargs)
    return LeocSAC(
        policy,
        env,
        learning_rate=config.critic_learning_rate,
        actor_learning_rate=config.actor_learning_rate,
        buffer_size=config.buffer_size,
        learning_starts=config.learning_starts,
        batch_size=config.batch_size,
        tau=config.polyak,
        gamma=config.discount,
        train_freq=config.train_freq,
        gradient_steps=config.gradient_steps,
        ent_coef=config.sac_entropy_coef,
        target_entropy=config.sac_target_entropy,
        target_update_interval=config.target_update_interval,
        warmup=config.warmup,
        critic_loss=config.critic_loss,
        action_noise=exploration_noise(config, env.action_space, seed)
        if config.sac_action_noise
        else None,
        policy_kwargs=policy_kwargs,
        seed=seed,
        device="cpu",
        verbose=0,
    )
