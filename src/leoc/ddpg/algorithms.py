r"""SB3's DDPG and TD3 with the settings of the LEOC paper and its authors' code that SB3 does
not expose.

Appendix C of Zhang & Capel (2021) uses different Adam step sizes for the actor (5e-4) and the
critic (1e-3), and soft target updates (factor 0.05) every 5 gradient updates. SB3 uses one
``learning_rate`` for both optimisers and updates the targets after every (actor) update.
:class:`LeocDDPG` and :class:`LeocTD3` add exactly these two options and otherwise *are* SB3's
algorithms (the training loop is SB3's own ``train``):

* ``actor_learning_rate``: the actor optimiser's step size (``learning_rate`` stays the
  critic's); ``None`` keeps SB3's behaviour. A learning-rate schedule scales both alike.
* ``target_update_interval``: soft target updates happen on every ``target_update_interval``-th
  of SB3's target-update opportunities (every update for DDPG, every ``policy_delay``-th for
  TD3); in between the Polyak coefficient is set to zero (``polyak`` keeps the nominal one).

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

The LEOC policy (:class:`leoc.ddpg.HybridTD3Policy`) also works with plain
``stable_baselines3.DDPG`` and ``TD3``; these classes only reproduce the paper's settings.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from stable_baselines3 import DDPG, TD3
from stable_baselines3.common.utils import polyak_update, update_learning_rate

from leoc.ddpg.config import CRITIC_LOSSES, WARMUPS

__all__ = [
    "CRITIC_LOSSES",
    "HUBER_DELTA",
    "ActorRateAndWarmupMixin",
    "LeocDDPG",
    "LeocTD3",
    "WARMUPS",
    "critic_loss_fn",
]

NO_TARGET_UPDATE = 0.0  # Polyak coefficient that leaves the targets unchanged
FULL_PROGRESS = 1.0  # SB3's "progress remaining" at the start of training
HUBER_DELTA = 1.0  # tf.compat.v1.losses.huber_loss's default delta (TF-Agents' DDPG)
NORMALISED_LIMIT = 1.0  # SB3's off-policy actions live in [-1, 1]


def critic_loss_fn(name: str) -> Any:
    """The elementwise-mean TD loss ``loss(q, target)`` called ``name`` (see the module)."""
    if name not in CRITIC_LOSSES:
        raise ValueError(f"critic_loss: expected one of {CRITIC_LOSSES}, found {name!r}")
    if name == "huber":
        return lambda q, target: F.huber_loss(q, target, delta=HUBER_DELTA)
    return F.mse_loss


class ActorRateAndWarmupMixin:
    """``actor_learning_rate`` and ``warmup`` for any SB3 off-policy algorithm with an actor.

    Shared by :class:`LeocDDPG`, :class:`LeocTD3` and :class:`leoc.ddpg.sac.LeocSAC`; see the
    module docstring for the two options. The class that mixes it in sets both attributes
    (through :meth:`_init_actor_rate_and_warmup`) before SB3 uses them.
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
        super()._update_learning_rate(optimizers)  # type: ignore[misc]
        if getattr(self, "actor_learning_rate", None) is None:
            return
        schedule = self.lr_schedule  # type: ignore[attr-defined]
        ratio = schedule(self._current_progress_remaining) / schedule(FULL_PROGRESS)  # type: ignore[attr-defined]
        update_learning_rate(self.actor.optimizer, self.actor_learning_rate * ratio)  # type: ignore[attr-defined,operator]

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


class LeocDDPG(_PaperSettingsMixin, DDPG):
    """SB3 ``DDPG`` plus ``actor_learning_rate``, ``target_update_interval``, ``warmup`` and
    ``critic_loss`` (see module)."""


class LeocTD3(_PaperSettingsMixin, TD3):
    """SB3 ``TD3`` plus ``actor_learning_rate``, ``target_update_interval``, ``warmup`` and
    ``critic_loss`` (see module)."""
