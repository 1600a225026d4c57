"""SB3's DDPG and TD3 with two settings of the LEOC paper that SB3 does not expose.

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

The LEOC policy (:class:`leoc.ddpg.HybridTD3Policy`) also works with plain
``stable_baselines3.DDPG`` and ``TD3``; these classes only reproduce the paper's settings.
"""

from __future__ import annotations

from typing import Any

import torch
from stable_baselines3 import DDPG, TD3
from stable_baselines3.common.utils import update_learning_rate

__all__ = ["LeocDDPG", "LeocTD3"]

NO_TARGET_UPDATE = 0.0  # Polyak coefficient that leaves the targets unchanged
FULL_PROGRESS = 1.0  # SB3's "progress remaining" at the start of training


class _PaperSettingsMixin:
    """Separate actor learning rate and target update interval for SB3's TD3 family."""

    actor_learning_rate: float | None
    target_update_interval: int
    polyak: float

    def __init__(
        self,
        *args: Any,
        actor_learning_rate: float | None = None,
        target_update_interval: int = 1,
        **kwargs: Any,
    ) -> None:
        super().__init__(*args, **kwargs)  # the SB3 algorithm after this mixin in the MRO
        self._init_paper_settings(actor_learning_rate, target_update_interval)

    def _init_paper_settings(
        self, actor_learning_rate: float | None, target_update_interval: int
    ) -> None:
        if actor_learning_rate is not None and not actor_learning_rate > 0:
            raise ValueError(f"actor_learning_rate: expected > 0, found {actor_learning_rate}")
        if isinstance(target_update_interval, bool) or not (
            isinstance(target_update_interval, int) and target_update_interval >= 1
        ):
            raise ValueError(
                f"target_update_interval: expected an int >= 1, found {target_update_interval!r}"
            )
        self.actor_learning_rate = actor_learning_rate
        self.target_update_interval = target_update_interval
        self.polyak = float(self.tau)  # type: ignore[attr-defined]

    def _update_learning_rate(
        self, optimizers: list[torch.optim.Optimizer] | torch.optim.Optimizer
    ) -> None:
        super()._update_learning_rate(optimizers)  # type: ignore[misc]
        if self.actor_learning_rate is None:
            return
        schedule = self.lr_schedule  # type: ignore[attr-defined]
        ratio = schedule(self._current_progress_remaining) / schedule(FULL_PROGRESS)  # type: ignore[attr-defined]
        update_learning_rate(self.actor.optimizer, self.actor_learning_rate * ratio)  # type: ignore[attr-defined]

    def train(self, gradient_steps: int, batch_size: int = 100) -> None:
        if self.target_update_interval == 1:
            super().train(gradient_steps, batch_size)  # type: ignore[misc]
            return
        delay = int(getattr(self, "policy_delay", 1))
        for _ in range(gradient_steps):
            # SB3 counts the update first, then updates actor and targets when it divides by
            # policy_delay; we keep every target_update_interval-th of those opportunities.
            update = self._n_updates + 1  # type: ignore[attr-defined]
            opportunity = update % delay == 0
            due = opportunity and (update // delay) % self.target_update_interval == 0
            self.tau = self.polyak if due else NO_TARGET_UPDATE
            super().train(1, batch_size)  # type: ignore[misc]
        self.tau = self.polyak


class LeocDDPG(_PaperSettingsMixin, DDPG):
    """SB3 ``DDPG`` plus ``actor_learning_rate`` and ``target_update_interval`` (see module)."""


class LeocTD3(_PaperSettingsMixin, TD3):
    """SB3 ``TD3`` plus ``actor_learning_rate`` and ``target_update_interval`` (see module)."""
