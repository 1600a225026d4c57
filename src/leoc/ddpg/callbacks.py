"""SB3 callback that evaluates on a separate environment, records the learning curve, keeps the
best model and drives a tqdm progress bar.

The curve is return against *interaction time*: environment steps and simulated seconds
(``steps * dt``). Evaluation episodes are the deterministic swing-up rollouts of
:mod:`leoc.ddpg.rollout`, always from the same seeded starts, so points are comparable.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from stable_baselines3.common.callbacks import BaseCallback

from leoc.ddpg.physical import PhysicalPolicy, physical_policy
from leoc.ddpg.rollout import EvaluationResult, evaluate_policy

__all__ = ["LearningCurveCallback"]

PROGRESS_REFRESH_STEPS = 50  # tqdm update granularity (keeps per-step overhead negligible)


class LearningCurveCallback(BaseCallback):
    """Evaluate every ``eval_interval`` steps (and at steps 0 and the end), keep the best.

    Parameters
    ----------
    eval_env : gymnasium.Env
        A separate environment instance (never the training one).
    system : leoc.systems.System
        Supplies ``dt``, ``episode_steps`` and ``main_coordinate`` for the hold test.
    eval_seeds : sequence of int
        One deterministic episode per seed.
    eval_interval : int
        Environment steps between evaluations.
    hold_band, min_hold_steps
        Hold test of :func:`leoc.ddpg.rollout.evaluate_policy`.
    save_best : callable, optional
        Called with the SB3 model whenever the mean return improves (saves ``best_model.zip``).
    progress : bool
        Show a tqdm progress bar over the total steps.
    total_steps : int
        Length of the progress bar.

    Attributes
    ----------
    curve : list of dict
        One row per evaluation: ``steps``, ``interaction_seconds``, ``mean_return``,
        ``std_return``, ``held_fraction``, ``returns``, ``hold_starts`` (per episode, the step
        from which it holds the operating point, ``None`` if it does not).
    best_policy : PhysicalPolicy or None
        Physical-units copy of the actor at the best evaluation.
    best_return : float
    """

    def __init__(
        self,
        eval_env: Any,
        system: Any,
        eval_seeds: Sequence[int],
        eval_interval: int,
        hold_band: float,
        min_hold_steps: int,
        save_best: Callable[[Any], None] | None = None,
        progress: bool = True,
        total_steps: int = 0,
    ) -> None:
        super().__init__(verbose=0)
        self.eval_env = eval_env
        self.system = system
        self.eval_seeds = list(eval_seeds)
        self.eval_interval = eval_interval
        self.hold_band = hold_band
        self.min_hold_steps = min_hold_steps
        self.save_best = save_best
        self.progress = progress
        self.total_steps = total_steps
        self.curve: list[dict[str, Any]] = []
        self.best_policy: PhysicalPolicy | None = None
        self.best_return = float("-inf")
        self._bar: Any = None
        self._bar_position = 0
        self._last_eval_step = -1

    def _on_training_start(self) -> None:
        if self.progress:
            from tqdm.auto import tqdm

            self._bar = tqdm(total=self.total_steps, unit="step", desc="train", leave=True)
        self._evaluate()

    def _on_step(self) -> bool:
        steps = self.num_timesteps
        if steps % PROGRESS_REFRESH_STEPS == 0 and self._bar is not None:
            self._bar.update(steps - self._bar_position)
            self._bar_position = steps
        if steps % self.eval_interval == 0:
            self._evaluate()
        return True

    def _on_training_end(self) -> None:
        if self._last_eval_step != self.num_timesteps:
            self._evaluate()
        if self._bar is not None:
            self._bar.update(self.num_timesteps - self._bar_position)
            self._bar.close()
            self._bar = None

    def _evaluate(self) -> EvaluationResult:
        policy = physical_policy(self.model.actor)
        result = evaluate_policy(
            policy,
            self.eval_env,
            self.system,
            self.eval_seeds,
            self.hold_band,
            self.min_hold_steps,
        )
        steps = int(self.num_timesteps)
        self._last_eval_step = steps
        self.curve.append(
            {
                "steps": steps,
                "interaction_seconds": steps * self.system.dt,
                "mean_return": result.mean_return,
                "std_return": result.std_return,
                "held_fraction": result.held_fraction,
                "returns": result.returns,
                "hold_starts": result.hold_starts,
            }
        )
        if result.mean_return > self.best_return:
            self.best_return = result.mean_return
            self.best_policy = policy
            if self.save_best is not None:
                self.save_best(self.model)
        if self._bar is not None:
            self._bar.set_postfix(
                eval_return=f"{result.mean_return:.1f}", held=f"{result.held_fraction:.0%}"
            )
        return result
