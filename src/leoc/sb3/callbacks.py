"""SB3 callback that evaluates on a separate environment, records the learning curve, keeps the
best model, selects the run's controller and drives a tqdm progress bar.

The curve is return against *interaction time*: environment steps and simulated seconds
(``steps * dt``). Evaluation episodes are those of the trainer contract (:mod:`leoc.training`):
deterministic swing-up episodes on the pure step function, from the same seeded starts at every
evaluation, so points are comparable and PILCO's curves are measured the same way.

Model selection (``MODEL_SELECTIONS`` of :mod:`leoc.sb3.config`): ``"final"`` (leoc's,
:mod:`leoc.training`) keeps the actor at the end of training; ``"best_last_third"`` restores, at the
end of training, the actor of the best evaluation (strictly highest mean return, the earliest on
ties) among those after :func:`last_third_start`, as nrjc/LEOC's ``dao/trainer.py`` does
(``DDPGTrainer.train`` saves the policy when ``iteration > int(num_iterations / 3 * 2)`` and the
evaluation return beats the best so far; that saved policy is their controller);
``"best_held"`` restores the actor of the evaluation, any of the run, that held the operating point
in the largest share of its episodes, the highest mean return among those (the earliest on ties):
the success test of a swing-up is holding, and a return alone can prefer a fast swing that falls
over to a slower one that holds. :func:`selection_key` and :func:`selection_start` are the rule,
shared with the ablation's re-selection (:func:`leoc.experiments.ablation.delivered_steps`).
Every rule judges the curve's nominal evaluation episodes, unless the run selects on plants of
its training distribution (``selection_plants``: :class:`LearningCurveCallback`).
"""

from __future__ import annotations

import copy
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from leoc.progress import evaluation_text, is_terminal, steps_line
from leoc.sb3.config import MODEL_SELECTIONS
from leoc.sb3.physical import PhysicalPolicy, physical_policy
from leoc.training import Evaluation, curve_row, evaluate_episodes, evaluate_on_plants

__all__ = [
    "MODEL_SELECTIONS",
    "HeldOutEvaluationCallback",
    "LearningCurveCallback",
    "last_third_start",
    "selection_key",
    "selection_start",
]

PROGRESS_REFRESH_STEPS = 50  # tqdm update granularity (keeps per-step overhead negligible)
PROGRESS_LINE_INTERVAL_S = 10.0
"""Seconds between the plain progress lines of ``progress="lines"``."""
SELECTION_FRACTION = 2.0 / 3.0  # the selection window opens after two thirds of the updates


def last_third_start(total_steps: int, learning_starts: int) -> int:
    """Environment step after which evaluations are candidates of ``"best_last_third"``.

    nrjc/LEOC (``dao/trainer.py``) counts ``num_iterations`` updates after its initial collect
    and keeps evaluations with ``iteration > int(num_iterations / 3 * 2)``; here the updates run
    from step ``learning_starts`` to ``total_steps``, so the window opens after step
    ``learning_starts + int((total_steps - learning_starts) * 2 / 3)``.
    """
    updates = max(total_steps - learning_starts, 0)
    return learning_starts + int(updates * SELECTION_FRACTION)


def selection_key(model_selection: str, mean_return: float, held_fraction: float) -> tuple:
    """What model selection ``model_selection`` maximises over its candidate evaluations (the
    earliest wins ties): ``(mean_return,)`` for ``"best_last_third"``, ``(held_fraction,
    mean_return)`` for ``"best_held"``; ``"final"`` selects nothing (``()``)."""
    if model_selection not in MODEL_SELECTIONS:
        raise ValueError(
            f"model_selection: expected one of {MODEL_SELECTIONS}, found {model_selection!r}"
        )
    if model_selection == "best_held":
        return (float(held_fraction), float(mean_return))
    if model_selection == "best_last_third":
        return (float(mean_return),)
    return ()


def selection_start(model_selection: str, total_steps: int, learning_starts: int) -> int:
    """Evaluations at steps strictly after this one are candidates of ``model_selection``:
    :func:`last_third_start` for ``"best_last_third"``, every evaluation (-1) otherwise."""
    if model_selection == "best_last_third":
        return last_third_start(total_steps, learning_starts)
    return -1


class LearningCurveCallback(BaseCallback):
    """Evaluate every ``eval_interval`` steps (and at steps 0 and the end), keep the best.

    Parameters
    ----------
    system : leoc.systems.System
        The system the evaluation episodes run on (its hold test, ``dt``).
    eval_starts : (E, S) array
        One deterministic episode per start (:func:`leoc.training.evaluation_starts`).
    eval_interval : int
        Environment steps between evaluations.
    save_best : callable, optional
        Called with the SB3 model whenever the mean return improves (saves ``best_model.zip``).
    progress : bool or "lines"
        True: a tqdm progress bar over the total steps on a terminal (plain lines when stderr
        is not one); ``"lines"``: a plain line (for a log file) every
        ``PROGRESS_LINE_INTERVAL_S`` seconds and after each evaluation, never the same line
        twice in a row: ``[ddpg] step K/N (P%), R steps/s, ETA T, last evaluation: return X,
        held H%`` (``leoc.progress.steps_line``; the algorithm's name in the brackets:
        ``label``).
    total_steps : int
        Length of the progress bar.
    model_selection : {"final", "best_last_third", "best_held"}
        Which actor the model holds at the end of training (see the module docstring).
    selection_start : int
        Evaluations at steps strictly after this one are selection candidates
        (:func:`selection_start`).
    label : str
        The learner's name in the progress lines (``ddpg``, ``td3``, ``sac``).
    selection_plants : sequence of sequences of Perturbation, optional
        One perturbed plant per start: model selection then judges on these episodes
        (:func:`leoc.training.evaluate_on_plants`) rather than on the curve's nominal ones,
        whose row records them under ``"selection"`` (``DDPGConfig.selection_plants``).

    Attributes
    ----------
    curve : list of dict
        One row per evaluation (:func:`leoc.training.curve_row`).
    best_policy : PhysicalPolicy or None
        Physical-units copy of the actor at the best evaluation.
    best_return : float
    selected_steps : int or None
        Step of the evaluation whose actor was restored (``"best_last_third"``,
        ``"best_held"``), else None.
    """

    def __init__(
        self,
        system: Any,
        eval_starts: np.ndarray,
        eval_interval: int,
        save_best: Callable[[Any], None] | None = None,
        progress: bool | str = True,
        total_steps: int = 0,
        model_selection: str = "final",
        selection_start: int = 0,
        label: str = "ddpg",
        selection_plants: Sequence[Sequence[Any]] | None = None,
    ) -> None:
        if model_selection not in MODEL_SELECTIONS:
            raise ValueError(
                f"model_selection: expected one of {MODEL_SELECTIONS}, found {model_selection!r}"
            )
        super().__init__(verbose=0)
        self.system = system
        self.eval_starts = np.asarray(eval_starts, dtype=float)
        self.eval_interval = eval_interval
        self.save_best = save_best
        self.progress = progress
        self.total_steps = total_steps
        self.curve: list[dict[str, Any]] = []
        self.best_policy: PhysicalPolicy | None = None
        self.best_return = float("-inf")
        self.model_selection = model_selection
        self.selection_start = int(selection_start)
        self.label = label
        self.selection_plants = None if selection_plants is None else list(selection_plants)
        if self.selection_plants is not None and len(self.selection_plants) != len(
            self.eval_starts
        ):
            raise ValueError(
                f"selection_plants: expected one per evaluation start ({len(self.eval_starts)}),"
                f" found {len(self.selection_plants)}"
            )
        self.selected_steps: int | None = None
        self._selected_key: tuple | None = None
        self._selected_actor: dict[str, Any] | None = None
        self._bar: Any = None
        self._bar_position = 0
        self._last_eval_step = -1
        self._lines = progress == "lines"
        self._started = time.monotonic()
        self._next_line = self._started + PROGRESS_LINE_INTERVAL_S
        self._last: Evaluation | None = None
        self._last_line = ""
        self._steps_at_start = 0

    def _on_training_start(self) -> None:
        self._started = time.monotonic()
        self._next_line = self._started + PROGRESS_LINE_INTERVAL_S
        self._steps_at_start = int(self.num_timesteps)
        if self.progress is True and not is_terminal(sys.stderr):
            self._lines = True  # a log file or a pipe: plain lines, not a bar's redraws
        elif self.progress is True:
            from tqdm.auto import tqdm

            self._bar = tqdm(total=self.total_steps, unit="step", desc="train", leave=True)
        self._bar_position = int(self.num_timesteps)
        if self._bar is not None:
            self._bar.update(self._bar_position)
        if self._last_eval_step != self.num_timesteps:  # a resumed run evaluated this step
            self._evaluate()

    def _on_step(self) -> bool:
        steps = self.num_timesteps
        if steps % PROGRESS_REFRESH_STEPS == 0:
            if self._bar is not None:
                self._bar.update(steps - self._bar_position)
                self._bar_position = steps
            if self._lines and time.monotonic() >= self._next_line:
                self._print_line()
        if steps % self.eval_interval == 0:
            self._evaluate()
        return True

    def progress_line(self) -> str:
        """``[LABEL] step K/N (P%), R steps/s, ETA T, last evaluation: return X, held H%``
        (``leoc.progress.steps_line``: the rate of this invocation's steps so far)."""
        last = self._last
        return steps_line(
            self.label,
            int(self.num_timesteps),
            self.total_steps,
            time.monotonic() - self._started,
            evaluation_text(last.mean_return, last.held_fraction) if last is not None else "",
            self._steps_at_start,
        )

    def _print_line(self) -> None:
        line = self.progress_line()
        if line != self._last_line:  # a stalled run prints nothing new
            print(line, flush=True)
            self._last_line = line
        self._next_line = time.monotonic() + PROGRESS_LINE_INTERVAL_S

    def _on_training_end(self) -> None:
        if self._last_eval_step != self.num_timesteps:
            self._evaluate()
        self.restore_selected()
        if self._bar is not None:
            self._bar.update(self.num_timesteps - self._bar_position)
            self._bar.close()
            self._bar = None

    def _evaluate(self) -> Evaluation:
        policy = physical_policy(self.model.actor)
        result = evaluate_episodes(self.system, policy, self.eval_starts)
        steps = int(self.num_timesteps)
        self._last_eval_step = steps
        row = curve_row(steps, self.system.dt, result)
        judged = result
        if self.selection_plants is not None:
            judged = evaluate_on_plants(
                self.system, policy, self.eval_starts, self.selection_plants
            )
            row["selection"] = {
                "mean_return": judged.mean_return,
                "held_fraction": judged.held_fraction,
                "returns": judged.returns,
                "hold_steps": judged.hold_steps,
            }
        self.curve.append(row)
        if result.mean_return > self.best_return:
            self.best_return = result.mean_return
            self.best_policy = policy
            if self.save_best is not None:
                self.save_best(self.model)
        self._last = result
        self._consider_for_selection(steps, judged)
        if self._bar is not None:
            self._bar.set_postfix(
                eval_return=f"{result.mean_return:.1f}", held=f"{result.held_fraction:.0%}"
            )
        if self._lines:
            self._print_line()
        return result

    #: Attributes a checkpoint keeps (:mod:`leoc.sb3.checkpoint`): the curve, the best
    #: return, the model selection's candidate, the step last evaluated and its result.
    CHECKPOINTED = (
        "curve",
        "best_return",
        "selected_steps",
        "_selected_key",
        "_selected_actor",
        "_last_eval_step",
        "_last",
    )

    def checkpoint_state(self) -> dict[str, Any]:
        """What a checkpoint keeps of this callback (:data:`CHECKPOINTED`)."""
        return copy.deepcopy({name: getattr(self, name) for name in self.CHECKPOINTED})

    def restore_checkpoint_state(self, state: dict[str, Any]) -> None:
        """Take back :meth:`checkpoint_state` before a resumed run's training starts."""
        for name in self.CHECKPOINTED:
            setattr(self, name, copy.deepcopy(state[name]))

    def restore_selected(self) -> None:
        """Load the selected actor into the model (no-op with ``"final"``)."""
        if self._selected_actor is not None:
            self.model.actor.load_state_dict(self._selected_actor)

    def _consider_for_selection(self, steps: int, result: Evaluation) -> None:
        """Keep a copy of the actor if this evaluation is the best candidate so far."""
        if self.model_selection == "final" or steps <= self.selection_start:
            return
        key = selection_key(self.model_selection, result.mean_return, result.held_fraction)
        if self._selected_key is None or key > self._selected_key:
            self._selected_key = key
            self.selected_steps = steps
            self._selected_actor = copy.deepcopy(self.model.actor.state_dict())


class HeldOutEvaluationCallback(BaseCallback):
    """Evaluate the current actor on held-out episodes at the learning curve's steps.

    Runs the deterministic actor (in physical units) from ``starts`` on ``system`` at step 0,
    every ``eval_interval`` environment steps, and at the end of training if the last step
    is not a multiple of ``eval_interval``: the steps at which :class:`LearningCurveCallback`
    evaluates. Nothing here feeds back into training or model selection, so these episodes
    measure the actor at each step without the optimism of a selection on them (the
    ablation's success test, :mod:`leoc.experiments.ablation`).

    Pass it to :func:`leoc.sb3.train_ddpg` in ``callbacks``: it runs before the learning-curve
    callback, so at the end of training it sees the final actor, before ``"best_last_third"``
    restores the selected one.

    Parameters
    ----------
    system : leoc.systems.System
        The system the episodes run on (its hold test); may step under other rules than the
        training environment.
    starts : (E, S) array
        One deterministic episode per start.
    eval_interval : int
        Environment steps between evaluations (the run's ``eval_interval``).

    Attributes
    ----------
    rows : list of dict
        One per evaluation: ``steps``, ``returns`` (per episode) and ``hold_steps`` (per
        episode, None where it did not hold; :meth:`leoc.systems.System.hold_step`).
    """

    def __init__(self, system: Any, starts: np.ndarray, eval_interval: int) -> None:
        valid = isinstance(eval_interval, int) and not isinstance(eval_interval, bool)
        if not valid or eval_interval < 1:
            raise ValueError(f"eval_interval: expected a positive int, found {eval_interval!r}")
        super().__init__(verbose=0)
        self.system = system
        self.starts = np.asarray(starts, dtype=float)
        self.eval_interval = eval_interval
        self.rows: list[dict[str, Any]] = []

    def _on_training_start(self) -> None:
        if not self.rows or self.rows[-1]["steps"] != self.num_timesteps:
            self._evaluate()

    def _on_step(self) -> bool:
        if self.num_timesteps % self.eval_interval == 0:
            self._evaluate()
        return True

    def checkpoint_state(self) -> list[dict[str, Any]]:
        """What a checkpoint keeps of this callback: its rows."""
        return copy.deepcopy(self.rows)

    def restore_checkpoint_state(self, state: list[dict[str, Any]]) -> None:
        """Take back :meth:`checkpoint_state` before a resumed run's training starts."""
        self.rows = copy.deepcopy(state)

    def _on_training_end(self) -> None:
        if not self.rows or self.rows[-1]["steps"] != self.num_timesteps:
            self._evaluate()

    def _evaluate(self) -> None:
        result = evaluate_episodes(self.system, physical_policy(self.model.actor), self.starts)
        self.rows.append(
            {
                "steps": int(self.num_timesteps),
                "returns": result.returns,
                "hold_steps": result.hold_steps,
            }
        )
